"""The `redundancy:` section's part in the configuration: its schema, problems, `_sys.redundancy.*` tags and alarm."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from softplc.adapters.redundancy.settings import SCHEMA, problems
from softplc.config.schema import Section
from softplc.core.datatypes import DataType
from softplc.core.tags import Access, TagDef

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig

PREFIX = "_sys.redundancy."
ROLE, MEMBER, ACTIVE, EPOCH, SERVICE_LEVEL = (PREFIX + name for name in ("role", "member", "active", "epoch", "service_level"))
PEER, PEER_OK, SYNC_AGE, SYNC_LAG, FAILOVERS = (PREFIX + name for name in ("peer", "peer_ok", "sync_age_ms", "sync_lag", "failovers"))
COORDINATOR_OK, DEGRADED, REFUSED, ACTIVE_HMI, ACTIVE_OPCUA, PEER_HMI = (
    PREFIX + name for name in ("coordinator_ok", "degraded", "refused", "active_hmi", "active_opcua", "peer_hmi"))

_TAGS: tuple[tuple[str, DataType, str, str], ...] = (
    (ROLE, DataType.STRING, "this runtime's role: ACTIVE, STANDBY, FENCED or STARTING", ""),
    (MEMBER, DataType.STRING, "this runtime's name in the pair", ""),
    (ACTIVE, DataType.STRING, "the name of the active runtime ('' while none is known)", ""),
    (EPOCH, DataType.UINT32, "the epoch of the active term (etcd revision): grows with every takeover", ""),
    (SERVICE_LEVEL, DataType.UINT16, "OPC UA ServiceLevel: 255/200 active, 100/50 standby, 1 fenced or starting", ""),
    (PEER, DataType.STRING, "the peer as this runtime sees it: in sync, connecting, gone, refused: why", ""),
    (PEER_OK, DataType.BOOL, "the peer is there and in sync", ""),
    (SYNC_AGE, DataType.FLOAT64, "standby: age of the last state applied; active: of the standby's last acknowledgement", "ms"),
    (SYNC_LAG, DataType.UINT32, "active: states sent and not yet acknowledged by the standby", ""),
    (FAILOVERS, DataType.UINT32, "times this runtime took over from an active", ""),
    (COORDINATOR_OK, DataType.BOOL, "the coordinator (etcd) answers", ""),
    (DEGRADED, DataType.BOOL, "the pair cannot fail over now: peer gone, sync lagging or coordinator unreachable", ""),
    (REFUSED, DataType.UINT32, "sync connections or messages refused (stranger, other configuration, malformed, replayed)", ""),
    (ACTIVE_HMI, DataType.STRING, "the active runtime's HMI address (for browsers to follow)", ""),
    (ACTIVE_OPCUA, DataType.STRING, "the active runtime's OPC UA endpoint (for clients to follow)", ""),
    (PEER_HMI, DataType.STRING, "the peer's HMI address", ""),
)


def tags(config: PlantConfig) -> list[TagDef]:
    if config.section("redundancy") is None:
        return []
    return [TagDef(name, kind, kind.default, unit=unit, description=text, access=Access.RO, group="_sys", runtime_only=True)
            for name, kind, text, unit in _TAGS]


def alarms(config: PlantConfig) -> list[tuple[tuple[str | int, ...], dict[str, Any]]]:
    if config.section("redundancy") is None:
        return []
    return [(("redundancy",), {
        "name": "redundancy_degraded", "discrete": {"tag": DEGRADED, "value": True}, "priority": "high",
        "message": "the redundant pair is degraded: {_sys.redundancy.peer}; a failure now stops the plant",
        "description": "The standby is gone or out of sync, or the coordinator (etcd) does not answer: no failover is possible until it is repaired.",
    })]


SECTION = Section(path=("redundancy",), schema=SCHEMA, problems=problems, tags=tags, alarms=alarms)
