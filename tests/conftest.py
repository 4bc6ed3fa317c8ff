"""Shared fixtures: build a plant from a YAML string, run it on the simulated clock."""

from __future__ import annotations

import textwrap
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from softplc.config import PlantConfig, load_config

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture
def make_config(tmp_path: Path) -> Callable[[str], PlantConfig]:
    """Write YAML text to tmp_path/tagdb.yaml and load it (programs/ resolves from the repo)."""

    def make(text: str, name: str = "tagdb.yaml") -> PlantConfig:
        path = tmp_path / name
        path.write_text(textwrap.dedent(text))
        return load_config(path)

    return make


@pytest.fixture(autouse=True)
def _log_summaries_stay_with_their_test():
    """Write the log flood summaries a test left open at its end, into its own output.

    A summary ("N more lines like this left out...") is written when its window closes or when
    logging is configured again: without this, the next test that configures logging (any CLI
    test) would find another test's summary in its stderr — which test depends on the order.
    """
    yield
    from softplc.util.logs import flush_summaries

    flush_summaries()


# -- storage backends (softplc.storage): SQLite, and a real PostgreSQL server ---------------------

_schema_counter = iter(range(1, 1_000_000))


@pytest.fixture(scope="session")
def postgres_server():
    """One PostgreSQL server for the session (initdb + pg_ctl on a free port), stopped at the end.

    Skipped with the reason when the server binaries are missing, except under CI (CI=true),
    where scripts/install-test-tools.sh must have installed them: there it fails.
    """
    from tests.postgres_server import PostgresServer, PostgresUnavailable
    from tests.tools_support import missing

    try:
        server = PostgresServer()
    except PostgresUnavailable as error:
        missing(str(error))
    server.start()
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture
def postgres_dsn(postgres_server) -> str:
    """A DSN to a fresh, empty schema of the session's PostgreSQL server."""
    return postgres_server.new_schema(f"test_{next(_schema_counter)}")


@pytest.fixture(params=["sqlite", "postgresql"])
def storage_settings(request, tmp_path: Path):
    """StorageSettings for a fresh, empty store: once on SQLite, once on PostgreSQL."""
    from softplc.storage import StorageSettings

    if request.param == "sqlite":
        return StorageSettings.sqlite(tmp_path / "store.sqlite", flush_period=0.05)
    return StorageSettings.postgresql(request.getfixturevalue("postgres_dsn"), flush_period=0.05)


# -- MQTT: a real mosquitto broker ------------------------------------------------------------------


@pytest.fixture
def mosquitto():
    """A mosquitto broker on a free loopback port for one test (stop() and start() it to restart it)."""
    from tests.mosquitto_server import MosquittoServer, MosquittoUnavailable

    server = _test_server(MosquittoServer, MosquittoUnavailable)
    server.start()
    try:
        yield server
    finally:
        server.remove()


def _test_server(make: Callable[[], Any], unavailable: type[Exception]) -> Any:
    """A server the test tools installed, or a skip with why — under CI (CI=true) a failure (tools_support.missing)."""
    from tools_support import missing

    try:
        return make()
    except unavailable as error:
        missing(str(error))


# -- etcd: the redundant pair's coordinator ----------------------------------------------------------


@pytest.fixture
def etcd():
    """A single-node etcd on free loopback ports for one test (stop() and start() it to restart it)."""
    from tests.etcd_server import EtcdServer, EtcdUnavailable

    server = _test_server(EtcdServer, EtcdUnavailable)
    server.start()
    try:
        yield server
    finally:
        server.remove()
