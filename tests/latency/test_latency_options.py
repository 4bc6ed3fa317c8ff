"""`softplc latency` options: endpoints and numbers are checked before anything starts."""

from __future__ import annotations

import pytest

from softplc.app.cli import build_parser
from softplc.latency import cli as command
from softplc.latency.cli import targets
from softplc.latency.endpoint import EndpointError, parse_endpoint


def parse(*argv: str):  # type: ignore[no-untyped-def]
    return build_parser().parse_args(["latency", *argv])


@pytest.mark.parametrize("text, protocol, host, port", [
    ("opc.tcp://10.0.0.5:4840/", "opcua", "10.0.0.5", 4840),
    ("opc.tcp://plc.local:4841/softplc/", "opcua", "plc.local", 4841),
    ("127.0.0.1:502", "modbus", "127.0.0.1", 502),
    ("modbus://plc:5020/", "modbus", "plc", 5020),
    ("tcp://plc:502", "modbus", "plc", 502),
    ("[::1]:502", "modbus", "::1", 502),
])
def test_endpoints_accepted(text, protocol, host, port):
    endpoint = parse_endpoint(text)
    assert (endpoint.protocol, endpoint.host, endpoint.port) == (protocol, host, port)


@pytest.mark.parametrize("text, reason", [
    ("garbage", "is no HOST:PORT"),
    ("http://x:1", "unknown scheme http://"),
    ("opc.tcp://", "names no host"),
    ("opc.tcp://plc", "names no port"),
    ("opc.tcp://plc:99999/", "from 1 to 65535"),
    ("plc:0", "from 1 to 65535"),
    ("plc:", "is no HOST:PORT"),
    (":502", "is no HOST:PORT"),
    ("a/b:502", "is no host name"),
])
def test_endpoints_refused(text, reason):
    with pytest.raises(EndpointError, match=reason):
        parse_endpoint(text)


def test_a_malformed_endpoint_is_refused_before_the_run():
    for text in ("garbage", "http://x:1", "opc.tcp://"):
        with pytest.raises(ValueError, match="--endpoint"):
            targets(parse("--endpoint", text))


@pytest.mark.parametrize("option, value, message", [
    ("--timeout", "-1", "must be more than 0 s"),
    ("--timeout", "0", "must be more than 0 s"),
    ("--poll-interval", "-5", "must be more than 0 ms"),
    ("--publishing-interval", "-1", "must be at least 0 ms"),
    ("--scan", "0.01", "must be at least 0.1 ms"),
    ("--scan", "nan", "out of range"),
    ("--samples", "0", "must be at least 1"),
    ("--duration", "0", "must be more than 0 s"),
    ("--unit-id", "256", "must be from 0 to 255"),
    ("--samples", "ten", "'ten' is not a whole number"),
])
def test_numbers_are_checked_by_the_parser(capsys, option, value, message):
    with pytest.raises(SystemExit) as exit:
        parse(option, value)
    assert exit.value.code == 2  # as every other option error
    assert f"argument {option}: " in capsys.readouterr().err
    with pytest.raises(SystemExit):
        parse(option, value)
    assert message in capsys.readouterr().err


def test_a_timeout_shorter_than_the_longest_task_is_refused():
    with pytest.raises(ValueError, match="longest task"):
        targets(parse("--scenario", "slow", "--timeout", "20"))
    assert targets(parse("--scenario", "slow", "--timeout", "31"))[0].timeout == 31


def test_help_tells_the_namespace_default(capsys):
    with pytest.raises(SystemExit):
        parse("--help")
    assert "urn:softplc:tags if the server has it" in " ".join(capsys.readouterr().out.split())


def test_ctrl_c_while_starting_is_no_traceback(monkeypatch, capsys):
    def interrupted(args):  # type: ignore[no-untyped-def]
        raise KeyboardInterrupt

    monkeypatch.setattr(command, "targets", interrupted)
    assert command.cmd_latency(parse("--samples", "3")) == command.EXIT_FAILURE
    assert "interrupted by the user" in capsys.readouterr().err
