"""Password logins: a flood of wrong passwords for one user locks nobody else out, fills no log,
and the password hash never runs on the event loop that runs the scan."""

from __future__ import annotations

import asyncio
import logging
import time

import pytest
import pytest_asyncio
from asyncua import Client, ua

from softplc.adapters.opcua import Role
from softplc.security import logins as logins_module
from softplc.security.logins import FAILURES_PER_PEER, FAILURES_PER_PEER_AND_USER, LoginThrottle, PasswordLogins
from softplc.security.passwords import SCRYPT_LOG2_N, verify_password
from softplc.security.users import UserStore
from tests.opcua_support import TEST_HASH_COST, client_for, running_plant

in_module_loop = pytest.mark.asyncio(loop_scope="module")


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def plant(tmp_path_factory: pytest.TempPathFactory):
    async with running_plant(tmp_path_factory.mktemp("opcua-logins"), security=("None",)) as (runtime, server):
        yield runtime, server


async def _log_in(server, user: str, password: str, timeout: float = 4) -> ua.StatusCode:
    """Good, or the status the server refused the login with."""
    try:
        async with client_for(server, user, password, timeout=timeout):
            return ua.StatusCode()
    except ua.UaStatusCodeError as refused:
        return ua.StatusCode(refused.code)


@in_module_loop
async def test_a_password_flood_on_one_user_locks_out_nobody_else(plant, caplog: pytest.LogCaptureFixture) -> None:
    _, server = plant
    caplog.set_level(logging.INFO)
    server.users.add("alice", Role.OPERATOR, "alice-password-1", log2_n=TEST_HASH_COST)
    server.users.add("bob", Role.OPERATOR, "bob-password-1", log2_n=TEST_HASH_COST)
    logins = server.user_manager.logins
    hashed = logins.hashed
    stop = asyncio.Event()

    async def guess(attacker: int) -> list[ua.StatusCode]:
        answers = []
        for attempt in range(15):
            if stop.is_set():
                break
            answers.append(await _log_in(server, "alice", f"guess-{attacker}-{attempt}"))
        return answers

    attackers = [asyncio.create_task(guess(number)) for number in range(3)]
    while logins.hashed < hashed + FAILURES_PER_PEER_AND_USER:  # until alice's budget from 127.0.0.1 is spent
        await asyncio.sleep(0.01)
    # bob has never logged in (nothing remembered): his password is checked during the flood.
    bob = await _log_in(server, "bob", "bob-password-1")
    stop.set()
    answers = [answer for attacker in attackers for answer in await attacker]
    assert bob.is_good()
    assert answers and all(answer.value == ua.StatusCodes.BadUserAccessDenied for answer in answers)
    assert logins.hashed - hashed == FAILURES_PER_PEER_AND_USER + 1  # the rest were refused without hashing
    # A few log lines, not one per attempt, and no asyncua error line per refused login.
    ours = [r for r in caplog.records if r.name.startswith(("softplc.adapters.opcua", "softplc.security.logins")) and r.levelno >= logging.WARNING and "login" in r.getMessage()]
    assert 1 <= len(ours) <= 2, [r.getMessage() for r in ours]
    assert not [r for r in caplog.records if r.name.startswith("asyncua") and r.levelno >= logging.ERROR]


@in_module_loop
async def test_the_event_loop_keeps_running_while_a_password_is_hashed(plant, monkeypatch: pytest.MonkeyPatch) -> None:
    runtime, server = plant
    entry = server.users.add("carol", Role.VIEWER, "carol-password-1")  # the default cost: ~0.4 s a check
    assert entry.password_hash is not None and entry.password_hash.startswith(f"scrypt${SCRYPT_LOG2_N}$8$1$")
    hashing: list[tuple[float, float]] = []

    def timed_verify(password: str, stored: str) -> bool:
        started = time.perf_counter()
        try:
            return verify_password(password, stored)
        finally:
            hashing.append((started, time.perf_counter()))

    monkeypatch.setattr(logins_module, "verify_password", timed_verify)
    ticks: list[float] = []

    async def ticker() -> None:
        while True:
            await asyncio.sleep(0.001)
            ticks.append(time.perf_counter())

    ticking = asyncio.create_task(ticker())
    cycles = runtime.tasks[0].stats.cycles
    try:
        assert (await _log_in(server, "carol", "carol-password-1", timeout=30)).is_good()
    finally:
        ticking.cancel()
    assert len(hashing) == 1  # the login was checked just now
    started, ended = hashing[0]
    # Had the hash run on the loop, the ticker could not have ticked while it ran.
    assert sum(1 for tick in ticks if started < tick < ended) >= 10, (ended - started, len(ticks))
    assert runtime.tasks[0].stats.cycles > cycles
    # Remembered: the next login of carol costs no hash.
    assert (await _log_in(server, "carol", "carol-password-1")).is_good()
    assert len(hashing) == 1


def test_throttle_counts_per_peer_and_user_per_peer_and_per_user() -> None:
    now = [0.0]
    throttle = LoginThrottle(window=60, clock=lambda: now[0])

    def fail(peer: str, user: str) -> None:
        throttle.started(peer, user)
        throttle.finished(peer, user, failed=True)

    for _ in range(FAILURES_PER_PEER_AND_USER):
        assert throttle.refusal("10.0.0.1", "alice") is None
        fail("10.0.0.1", "alice")
    assert throttle.refusal("10.0.0.1", "alice") is not None
    assert throttle.refusal("10.0.0.1", "bob") is None  # another user from the same address
    assert throttle.refusal("10.0.0.2", "alice") is None  # the same user from another address
    throttle.started("10.0.0.3", "dave")  # a check under way counts as a failure until it ends
    for _ in range(FAILURES_PER_PEER_AND_USER - 1):
        fail("10.0.0.3", "dave")
    assert throttle.refusal("10.0.0.3", "dave") is not None
    throttle.finished("10.0.0.3", "dave", failed=False)
    assert throttle.refusal("10.0.0.3", "dave") is None
    for number in range(FAILURES_PER_PEER):  # spraying user names from one address
        fail("10.0.0.4", f"user{number}")
    assert throttle.refusal("10.0.0.4", "bob") is not None and throttle.refusal("10.0.0.5", "bob") is None
    now[0] = 61.0  # the window has passed
    assert throttle.refusal("10.0.0.1", "alice") is None and throttle.refusal("10.0.0.4", "bob") is None


class _RawPasswordClient(Client):
    """An asyncua client that sends its password bytes as they are (a client may send any bytes)."""

    raw_password = b""

    def _add_user_auth(self, params: ua.ActivateSessionParameters, username: str | None, password: str | None) -> None:
        super()._add_user_auth(params, username, password)
        params.UserIdentityToken.Password = self.raw_password


async def _log_in_raw(server, user: str, password: bytes) -> ua.StatusCode:
    client = _RawPasswordClient(server.endpoint, timeout=4)
    client.raw_password = password
    client.set_user(user)
    client.set_password("placeholder")
    try:
        async with client:
            return ua.StatusCode()
    except ua.UaStatusCodeError as refused:
        return ua.StatusCode(refused.code)


@in_module_loop
async def test_credentials_that_are_not_utf8_are_refused_cleanly_and_logged_once(plant, caplog: pytest.LogCaptureFixture) -> None:
    _, server = plant
    caplog.set_level(logging.INFO)
    caplog.clear()
    attempts = [
        ("op\udcff\udcfeerator", b"operator-pass-1"),  # the user name's bytes 6f 70 ff fe ...: not UTF-8
        ("operator", b"\xff\xfe-password"),  # the password's
    ] * 3
    answers = [await _log_in_raw(server, user, password) for user, password in attempts]
    refusals = {ua.StatusCodes.BadUserAccessDenied, ua.StatusCodes.BadIdentityTokenInvalid}
    assert all(answer.value in refusals for answer in answers), [answer.name for answer in answers]
    assert not [record for record in caplog.records if record.exc_info or record.levelno >= logging.ERROR], caplog.text
    lines = [record.getMessage() for record in caplog.records if "UTF-8" in record.getMessage()]
    assert len(lines) == 1, caplog.text  # one line for the peer; the other attempts are counted for its summary
    assert "refused" in lines[0] and "127.0.0.1" in lines[0]
    async with client_for(server) as anonymous:  # the server still serves (anonymous: no login budget spent)
        assert await anonymous.get_node("ns=2;s=s1").read_value() == "hello"


async def test_the_hmi_login_check_refuses_lone_surrogates_from_json_without_hashing(tmp_path, caplog: pytest.LogCaptureFixture) -> None:
    # JSON may carry "\udcff" in a user name: the HMI hands it to the same login check.
    store = UserStore(tmp_path / "users.yaml")
    store.add("operator", Role.OPERATOR, "operator-pass-1", log2_n=TEST_HASH_COST)
    logins = PasswordLogins(store, service="HMI")
    try:
        assert await logins.check("10.0.0.9", "oper\ud800ator", "operator-pass-1") is False
        assert await logins.check("10.0.0.9", "operator", "pass\udcff") is False
        assert await logins.check("10.0.0.9", "operator", "operator-pass-1") is True
    finally:
        logins.close()
    assert logins.hashed == 1
    lines = [record.getMessage() for record in caplog.records if "UTF-8" in record.getMessage()]
    assert lines == ["HMI: login from 10.0.0.9 refused: its user name or password is not valid UTF-8 (user name 'oper\\ud800ator')"]
