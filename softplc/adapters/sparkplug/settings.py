"""The `sparkplug:` section resolved: ids, devices and their metrics, command role, store.

    sparkplug:
      group_id: plant1                 # required
      edge_node_id: line1              # default: the plant's name
      primary_host: scada              # wait for spBv1.0/STATE/scada online before the births; store while it is away
      devices:                         # default: one device per template instance, and "plant" for the other tags
        - template: robot              # one device per instance (r01, r02...), metrics named by the template's tags
        - {template: task, id: "task-{instance}"}
        - {id: line, tags: ["conveyor_*", "hmi_*"], role: viewer}
      commands: {role: operator, user: scada, clock_tolerance: 2s}
      store: {enabled: true, max_size: 10MB}
      aliases: true
      properties: true

A tag belongs to the first device that claims it. `_sys.` tags are published only by a pattern
that itself starts with `_sys.`, and `_sys.sparkplug.*` never (they change with every message).
"""

from __future__ import annotations

import argparse
import fnmatch
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from softplc.core.roles import Role
from softplc.core.tags import Access, TagDef
from softplc.protocols.sparkplug.datatypes import FOR_TAG_TYPE
from softplc.protocols.sparkplug.metrics import MetricDefinition
from softplc.protocols.sparkplug.topics import id_problem
from softplc.util.durations import parse_duration
from softplc.util.suggest import did_you_mean

if TYPE_CHECKING:
    from softplc.config.plant import PlantConfig

SECTION = "sparkplug"
OWN_PREFIX = "_sys.sparkplug."
DEFAULT_DEVICE = "plant"
DEFAULT_MAX_SIZE = 10 * 1024 * 1024
DEFAULT_TOLERANCE = 2.0  # seconds a command's timestamp may lie before the birth (clock skew)

Problem = tuple[tuple[Any, ...], str]  # (path in the file, message)


@dataclass(frozen=True)
class Device:
    """A Sparkplug device: an id, its metrics (tag name → definition) and the role of its DCMD writes."""

    id: str
    metrics: dict[str, MetricDefinition]  # by tag name, in birth order
    role: Role

    @property
    def by_name(self) -> dict[str, tuple[str, MetricDefinition]]:
        return {definition.name: (tag, definition) for tag, definition in self.metrics.items()}


@dataclass(frozen=True)
class SparkplugSettings:
    """A checked `sparkplug:` section."""

    group_id: str
    edge_node_id: str
    devices: tuple[Device, ...]
    primary_host: str | None = None
    aliases: bool = True
    properties: bool = True
    role: Role = Role.OPERATOR
    user: str = ""
    clock_tolerance: float = DEFAULT_TOLERANCE
    store_enabled: bool = True
    store_max_size: int = DEFAULT_MAX_SIZE
    enabled: bool = True
    sim: bool = False

    def state_dir(self, plant_state_dir: Path) -> Path:
        """Where this edge node keeps its bdSeq and its store, under the plant's state directory."""
        return plant_state_dir / "sparkplug" / self.group_id / self.edge_node_id

    @classmethod
    def from_config(cls, config: PlantConfig) -> SparkplugSettings:
        """The settings of a checked configuration (its problems were reported by `problems`)."""
        settings, _ = resolve(config)
        assert settings is not None, "sparkplug: build() on a configuration with problems"
        return settings


def problems(config: PlantConfig) -> list[Problem]:
    """What the schema cannot say of `sparkplug:` (ids, devices that match nothing, durations, sizes)."""
    return resolve(config)[1] if isinstance(config.raw.get(SECTION), dict) else []


def resolve(config: PlantConfig) -> tuple[SparkplugSettings | None, list[Problem]]:
    """The settings and the problems of the section (settings None when there are problems)."""
    section = config.raw.get(SECTION)
    section = section if isinstance(section, dict) else {}
    found: list[Problem] = []

    def at(path: tuple[Any, ...], message: str) -> None:
        found.append(((SECTION, *path), message))

    group = section.get("group_id", "")
    node = section.get("edge_node_id", config.name)
    for key, value, what in (("group_id", group, "group_id"), ("edge_node_id", node, "edge_node_id")):
        message = id_problem(value, what)
        if message:
            at((key,) if key in section else (), message)
    host = section.get("primary_host")
    if host is not None and (message := id_problem(host, "primary_host")):
        at(("primary_host",), message)
    commands = section.get("commands") if isinstance(section.get("commands"), dict) else {}
    role = Role(commands.get("role", "operator"))
    tolerance = DEFAULT_TOLERANCE
    if "clock_tolerance" in commands:
        try:
            tolerance = parse_duration(commands["clock_tolerance"])
        except (TypeError, ValueError) as error:
            at(("commands", "clock_tolerance"), f"bad clock_tolerance {commands['clock_tolerance']!r}: {error}")
    store = section.get("store") if isinstance(section.get("store"), dict) else {}
    max_size = DEFAULT_MAX_SIZE
    if "max_size" in store:
        try:
            max_size = _size(store["max_size"])
        except ValueError as error:
            at(("store", "max_size"), str(error))
    devices = _devices(config, section.get("devices"), role, bool(section.get("aliases", True)), at)
    if found:
        return None, found
    return SparkplugSettings(
        group_id=group, edge_node_id=node, devices=tuple(devices), primary_host=host,
        aliases=bool(section.get("aliases", True)), properties=bool(section.get("properties", True)),
        role=role, user=str(commands.get("user") or host or "sparkplug-host"), clock_tolerance=tolerance,
        store_enabled=bool(store.get("enabled", True)), store_max_size=max_size,
        enabled=bool(section.get("enabled", True)), sim=bool(section.get("sim", False)),
    ), found


def _devices(config: PlantConfig, specs: Any, default_role: Role, aliases: bool, at: Callable[[tuple[Any, ...], str], None]) -> list[Device]:
    from softplc.config.system_tags import runtime_tag_definitions

    definitions = [*config.tags, *runtime_tag_definitions(config)]
    by_name = {definition.name: definition for definition in definitions}
    claimed: set[str] = set()
    devices: list[Device] = []
    next_alias = [1]  # aliases are unique across the node (§6.4.5); bdSeq and Rebirth have none

    def add(device_id: str, members: Sequence[tuple[str, TagDef]], role: Role, where: tuple[Any, ...]) -> None:
        if (message := id_problem(device_id, "device id")) is not None:
            at(where, message)
            return
        if any(device.id == device_id for device in devices):
            at(where, f"device id '{device_id}' is used twice")
            return
        metrics: dict[str, MetricDefinition] = {}
        for metric_name, tag in members:
            if tag.name in claimed:
                continue
            claimed.add(tag.name)
            metrics[tag.name] = _metric(metric_name, tag, role, next_alias[0] if aliases else None)
            next_alias[0] += 1
        devices.append(Device(device_id, metrics, role))

    if specs is None:  # the default: a device per template instance, one for the rest
        for template, instances in config.instances.items():
            for instance in instances:
                add(instance, _template_members(config, by_name, template, instance), default_role, ())
        rest = [(d.name, d) for d in config.tags if d.name not in claimed]
        if rest:
            add(DEFAULT_DEVICE if DEFAULT_DEVICE not in {d.id for d in devices} else "plant_tags", rest, default_role, ())
        return [device for device in devices if device.metrics]
    for index, spec in enumerate(specs if isinstance(specs, list) else []):
        where = ("devices", index)
        if not isinstance(spec, dict):
            continue
        role = Role(spec["role"]) if "role" in spec else default_role
        if ("template" in spec) == ("tags" in spec):
            at(where, "a device names either a 'template' (a device per instance) or 'tags' (patterns), not both")
            continue
        if "template" in spec:
            template = spec["template"]
            if template not in config.instances:
                at((*where, "template"), f"unknown template '{template}'{did_you_mean(str(template), config.instances)}")
                continue
            id_format = str(spec.get("id", "{instance}"))
            if "{instance}" not in id_format:
                at((*where, "id"), f"the id of a template's devices must contain {{instance}} (one device per instance), not {id_format!r}")
                continue
            before = len(devices)
            for instance in config.instances[template]:
                add(id_format.replace("{instance}", instance), _template_members(config, by_name, template, instance), role, (*where, "id"))
            if all(not device.metrics for device in devices[before:]):
                at(where, f"the devices of template '{template}' have no tag left: earlier devices claimed them all")
            continue
        if "id" not in spec:
            at(where, "a device by tag patterns needs an 'id'")
            continue
        patterns = [spec["tags"]] if isinstance(spec["tags"], str) else list(spec["tags"])
        members = [(d.name, d) for d in definitions if d.name not in claimed and _matches(d.name, patterns)]
        if not members:
            at((*where, "tags"), f"the patterns {', '.join(map(repr, patterns))} match no tag (that an earlier device did not claim)")
            continue
        add(str(spec["id"]), members, role, (*where, "id"))
    return devices


def _template_members(config: PlantConfig, by_name: dict[str, TagDef], template: str, instance: str) -> list[tuple[str, TagDef]]:
    """The tags of one instance of a template, each with its name inside the template (iBM, xpos...)."""
    members = []
    for name, path in config.tag_paths.items():
        if len(path) >= 4 and path[:2] == ("templates", template) and name == f"{instance}_{path[3]}" and name in by_name:
            members.append((str(path[3]), by_name[name]))
    return members


def _matches(name: str, patterns: Sequence[str]) -> bool:
    if name.startswith(OWN_PREFIX):
        return False  # our own status tags change with every message we send
    system = name.startswith("_sys.")
    return any(fnmatch.fnmatchcase(name, pattern) for pattern in patterns if pattern.startswith("_sys.") or not system)


def _metric(name: str, tag: TagDef, role: Role, alias: int | None) -> MetricDefinition:
    # readOnly says what a DCMD can do: the tag database refuses the same writes (softplc.core.roles).
    writable = role.may_write and not tag.runtime_only and (tag.access is Access.RW or role.may_write_read_only)
    return MetricDefinition(name=name, datatype=FOR_TAG_TYPE[tag.type], alias=alias, unit=tag.unit, low=tag.min,
                            high=tag.max, description=tag.description, read_only=not writable)


def _size(value: Any) -> int:
    from softplc.util.logs import parse_size

    if isinstance(value, int) and not isinstance(value, bool):
        size = value
    else:
        try:
            size = parse_size(str(value))
        except argparse.ArgumentTypeError:
            raise ValueError(f"max_size {value!r} is not a size; write e.g. 10MB, 512KB or 1048576") from None
    if size < 64 * 1024:
        raise ValueError(f"max_size {value!r} is too small for the store: at least 64KB")
    return size
