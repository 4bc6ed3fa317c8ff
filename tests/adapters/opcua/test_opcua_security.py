"""OPC UA security over loopback: Sign and SignAndEncrypt with the generated server certificate, the
client-certificate trust store (untrusted → rejected/, trusted with the CLI), certificate logins,
anonymous off, and SecurityPolicy None only when configured."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
import pytest_asyncio
from asyncua import Client, ua

from softplc.adapters.opcua import Pki, Role, UserStore
from softplc.protocols.opcua_client import make_client
from softplc.security.certificates import fingerprint
from tests.conftest import REPO
from tests.opcua_support import PASSWORDS, client_for, make_client_certificate, running_plant, wait_until

pytestmark = pytest.mark.asyncio(loop_scope="module")

SIGN, ENCRYPT = ua.MessageSecurityMode.Sign, ua.MessageSecurityMode.SignAndEncrypt


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def secure(tmp_path_factory: pytest.TempPathFactory):
    directory = tmp_path_factory.mktemp("opcua-secure")
    async with running_plant(directory, security=("Basic256Sha256_Sign", "Basic256Sha256_SignAndEncrypt"), anonymous="off") as (runtime, server):
        yield directory, runtime, server


async def _secured(server, certificate, mode, user: str | None = "operator", password: str | None = None) -> Client:
    security = "Basic256Sha256_Sign" if mode == SIGN else "Basic256Sha256_SignAndEncrypt"
    return await make_client(server.endpoint, user=user, password=password if password is not None else (PASSWORDS[user] if user else None),
                             certificate=certificate, security=security)


def _cli(directory: Path, *arguments: str) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    return subprocess.run(
        [sys.executable, "-m", "softplc.app.cli", *arguments, "--config", str(directory / "tagdb.yaml"), "--state-dir", str(directory / "state")],
        capture_output=True, text=True, timeout=60, env=env, cwd=directory,
    )


async def test_server_certificate_made_on_first_start_and_only_secure_endpoints(secure) -> None:
    directory, _, server = secure
    pki = directory / "state" / "pki"
    assert (pki / "own" / "cert.der").is_file() and (pki / "own" / "key.pem").is_file()
    assert (pki / "own" / "key.pem").stat().st_mode & 0o077 == 0
    endpoints = await Client(server.endpoint).connect_and_get_server_endpoints()
    offered = {(e.SecurityPolicyUri.rsplit("#", 1)[-1], e.SecurityMode) for e in endpoints}
    assert offered == {("Basic256Sha256", SIGN), ("Basic256Sha256", ENCRYPT)}
    for endpoint in endpoints:
        token_types = {token.TokenType for token in endpoint.UserIdentityTokens}
        assert ua.UserTokenType.Anonymous not in token_types and ua.UserTokenType.UserName in token_types
    assert fingerprint(endpoints[0].ServerCertificate) == fingerprint((pki / "own" / "cert.der").read_bytes())


async def test_untrusted_certificate_is_rejected_kept_and_then_trusted_with_the_cli(secure) -> None:
    directory, runtime, server = secure
    certificate = make_client_certificate(directory, "untrusted-client")
    client = await _secured(server, certificate, SIGN)
    with pytest.raises(ua.UaStatusCodeError) as refused:
        async with client:
            pass
    assert refused.value.code == ua.StatusCodes.BadCertificateUntrusted
    rejected = list((directory / "state" / "pki" / "rejected").iterdir())
    assert [fingerprint(path.read_bytes()) for path in rejected] == [fingerprint(certificate.der)]

    listing = _cli(directory, "opcua", "certs")
    assert listing.returncode == 0, listing.stderr
    assert fingerprint(certificate.der)[:16] in listing.stdout.split("rejected client certificates")[1]
    trusted = _cli(directory, "opcua", "trust", fingerprint(certificate.der)[:12])
    assert trusted.returncode == 0, trusted.stderr
    assert not list((directory / "state" / "pki" / "rejected").iterdir())

    for mode in (SIGN, ENCRYPT):  # now trusted: both modes work, without a restart
        client = await _secured(server, certificate, mode)
        async with client:
            ns = await client.get_namespace_index("urn:softplc:tags")
            assert await client.get_node(ua.NodeId("s1", ns)).read_value() == "hello"
            results = await client.write_values([client.get_node(ua.NodeId("i32", ns))], [ua.Variant(int(mode), ua.VariantType.Int32)])
            assert results[0].is_good()
            await wait_until(lambda: runtime.db.value("i32") == int(mode))


async def test_wrong_password_and_anonymous_are_refused_on_a_trusted_channel(secure) -> None:
    directory, _, server = secure
    certificate = make_client_certificate(directory, "trusted-client")
    assert _cli(directory, "opcua", "trust", str(certificate.certificate)).returncode == 0
    for user, password, code in (("operator", "wrong-password", ua.StatusCodes.BadUserAccessDenied), (None, None, ua.StatusCodes.BadIdentityTokenRejected)):
        client = await _secured(server, certificate, ENCRYPT, user, password)
        with pytest.raises(ua.UaStatusCodeError) as refused:
            async with client:
                pass
        assert refused.value.code == code


async def test_a_certificate_can_log_a_user_in(secure) -> None:
    directory, runtime, server = secure
    certificate = make_client_certificate(directory, "robot-agent")
    assert _cli(directory, "opcua", "trust", str(certificate.certificate)).returncode == 0
    UserStore(directory / "state" / "users.yaml").add("robot7", Role.ENGINEER, certificate=fingerprint(certificate.der))
    client = await make_client(server.endpoint, certificate=certificate, security="Basic256Sha256_SignAndEncrypt", login_with_certificate=True)
    async with client:
        ns = await client.get_namespace_index("urn:softplc:tags")
        # An engineer may write the ro tag: proof the certificate mapped to robot7's role.
        results = await client.write_values([client.get_node(ua.NodeId("ro_i32", ns))], [ua.Variant(77, ua.VariantType.Int32)])
        assert results[0].is_good()
        await wait_until(lambda: runtime.db.value("ro_i32") == 77)


async def test_a_none_channel_serves_discovery_only_when_none_is_not_offered(secure) -> None:
    _, _, server = secure
    # asyncua's own client refuses early (no None endpoint); a raw client that insists gets
    # its endpoints on a None channel, but no session.
    client = client_for(server, "operator", timeout=2)
    await client.connect_socket()
    try:
        await client.send_hello()
        await client.open_secure_channel()
        assert await client.get_endpoints()
        with pytest.raises(ua.UaStatusCodeError) as refused:
            await client.create_session()
        assert refused.value.code == ua.StatusCodes.BadSecurityPolicyRejected
    finally:
        client.disconnect_socket()



async def test_an_untrusted_channel_certificate_gets_no_session_even_if_create_session_omits_it(secure) -> None:
    directory, _, server = secure
    certificate = make_client_certificate(directory, "sneaky-client")
    client = await _secured(server, certificate, ENCRYPT)
    send_create_session = client.uaclient.create_session

    async def without_certificate(params: ua.CreateSessionParameters):
        params.ClientCertificate = None  # asyncua's server then checked no certificate at all
        return await send_create_session(params)

    client.uaclient.create_session = without_certificate
    with pytest.raises(ua.UaStatusCodeError) as refused:
        async with client:
            pass
    assert refused.value.code == ua.StatusCodes.BadCertificateUntrusted


async def test_a_certificate_for_another_application_uri_is_refused(secure) -> None:
    directory, _, server = secure
    certificate = make_client_certificate(directory, "uri-client")  # issued for urn:softplc:client:uri-client
    Pki(directory / "state" / "pki").trust(str(certificate.certificate))
    client = await _secured(server, certificate, ENCRYPT)
    client.application_uri = "urn:example:someone-else"  # the description no longer matches the certificate
    with pytest.raises(ua.UaStatusCodeError) as refused:
        async with client:
            pass
    assert refused.value.code == ua.StatusCodes.BadCertificateUriInvalid
    async with await _secured(server, certificate, ENCRYPT) as honest:  # its own URI: welcome
        assert await honest.get_node(server.node_id("s1")).read_value() == "hello"
