"""The section registry: owners declare their part of tagdb.yaml, and check, run and schema use it."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

import jsonschema
import pytest
from conftest import REPO

from softplc.app.cli import main
from softplc.config import load_config, schema, sections
from softplc.config.schema import RegistryError, Section
from softplc.config.yamlsource import ConfigError
from softplc.core.roles import Role

HEAVY = ("asyncua", "pymodbus", "numpy", "scipy", "sklearn", "matplotlib", "jsonschema")


def _reset() -> None:
    sections.registered.cache_clear()
    sections.config_schema.cache_clear()


@pytest.fixture
def with_notebook(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """The registry with the example owner of tests/section_example.py added."""
    import section_example

    from softplc.config.manifest import Manifest, manifests

    example = Manifest(name="notebook", title="notebook", order=99, build=lambda config, args: [], sections=(section_example.SECTION,))
    monkeypatch.setattr(sections, "manifests", lambda: (*manifests(), example))
    _reset()
    yield
    monkeypatch.undo()
    _reset()


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "plant.yaml"
    path.write_text(textwrap.dedent(text))
    return path


PLANT = f"""\
    version: 1
    notebook: {{database: h.sqlite, interval: 1s}}
    templates:
      robot:
        instances: [r01, r02]
        notebook: {{deadband: 0.5}}
        tags:
          xpos: {{type: float64, notebook: {{enabled: false}}}}
          ypos: {{type: float64}}
    tags:
      level: {{type: float32, notebook: {{deadband: 2}}}}
      plain: {{type: float32}}
    tasks:
      fast:
        interval: 10ms
        programs:
          - name: sum
            program: {REPO / "tests" / "configs" / "sample_programs.py"}:Summer
            record: true
            bind: {{parts: [r01_xpos, r02_xpos], total: level, scans: plain}}
"""


def test_every_owner_module_is_light_to_import() -> None:
    # Loading a configuration imports every owner; `softplc --help` and `softplc schema` must stay fast.
    script = ("import sys, json; from softplc.config.sections import editor_schema; editor_schema(); "
              f"print(json.dumps(sorted({{n.split('.')[0] for n in sys.modules}} & set({list(HEAVY)!r}))))")
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=REPO, timeout=60, check=True)
    assert json.loads(result.stdout) == []


def test_the_existing_owners_are_registered_with_their_sections_and_keys() -> None:
    paths = [section.path for section in sections.registered()]
    # the runtime's, then each adapter's in start order (softplc/config/manifest.py)
    assert paths == [("runtime",), ("redundancy",), ("audit",), ("alarms",), ("mqtt",), ("fleet",), ("vda5050",), ("history",), ("links",), ("servers", "opcua"),
                     ("servers", "modbus"), ("sparkplug",), ("servers", "hmi"), ("hmi",)]
    assert set(sections.tag_keys()) == {"modbus", "history", "link"}
    properties = sections.config_schema()["properties"]
    assert set(properties["servers"]["properties"]) == {"opcua", "modbus", "hmi"}
    assert "modbus" in properties["tags"]["additionalProperties"]["properties"]


def test_a_new_owner_plugs_in_its_section_tag_template_and_program_keys(with_notebook, tmp_path: Path) -> None:
    config = load_config(write(tmp_path, PLANT))
    assert config.section("notebook") == {"database": "h.sqlite", "interval": "1s"}
    # a template's key applies to each instance's tags; a tag's own mapping is merged over it
    assert config.tag("r01_ypos").options == {"notebook": {"deadband": 0.5}}
    assert config.tag("r02_xpos").options == {"notebook": {"deadband": 0.5, "enabled": False}}
    assert config.tag("level").options == {"notebook": {"deadband": 2}}
    assert config.tag("plain").options == {}
    assert config.tasks[0].programs[0].options == {"record": True}
    # and `softplc schema` tells editors about it
    printed = sections.editor_schema()
    assert "notebook" in printed["properties"] and "record" in json.dumps(printed)
    jsonschema.Draft202012Validator.check_schema(printed)


def test_without_its_owner_the_keys_are_unknown(tmp_path: Path) -> None:
    path = write(tmp_path, "version: 1\nnotebook: {}\ntags:\n  a: {type: float32, notebook: {deadband: 1}}\n")
    with pytest.raises(ConfigError) as caught:
        load_config(path)
    top, tag = [str(p) for p in caught.value.problems]
    assert top.startswith(f"{path}:2:1: unknown key 'notebook'; expected one of: version, plant, templates, tags, tasks, runtime, redundancy, audit, alarms, mqtt, fleet, vda5050")
    assert tag.startswith(f"{path}:4:22: unknown key 'notebook'; expected one of: type, initial, unit, description, access, min, max, retain, group, shared_output, history")
    assert "notebook" not in top.split("expected one of:")[1] and "notebook" not in tag.split("expected one of:")[1]


def test_an_owners_schema_and_its_check_report_located_problems(with_notebook, tmp_path: Path, capsys) -> None:
    path = write(tmp_path, """\
        version: 1
        notebook: {interval: 10 parsecs}
        templates:
          robot:
            instances: [r01, r02]
            notebook: {deadband: 1}
            tags:
              name: {type: string}
        tags:
          label: {type: string, notebook: {deadband: 1}}
          level: {type: float32, notebook: {deadband: -1}}
        """)
    assert main(["check", str(path)]) == 2
    # the schema first: the owner's check runs only on a file whose structure is sound
    assert capsys.readouterr().err.splitlines() == [f"{path}:11:47: 'deadband' must be at least 0, not -1", "1 problem found"]
    path.write_text(path.read_text().replace("deadband: -1", "deadband: 1"))
    assert main(["check", str(path)]) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"{path}:2:22: bad interval '10 parsecs': write a duration such as 10ms, 100ms or 1s",
        f"{path}:6:26: a deadband needs a numeric tag, and 'r01_name' is string",
        f"{path}:6:26: a deadband needs a numeric tag, and 'r02_name' is string",
        f"{path}:10:46: a deadband needs a numeric tag, and 'label' is string",
        "4 problems found",
    ]


def test_owners_cannot_claim_the_same_section_or_key_or_a_core_one() -> None:
    modbus = Section(path=("servers", "modbus"), schema={}, tag_keys={"modbus": {}})
    with pytest.raises(RegistryError, match="section claimed by two owners"):
        schema.check_registry((modbus, Section(path=("servers", "modbus"), schema={})))
    with pytest.raises(RegistryError, match="tag key claimed by two owners: modbus"):
        schema.check_registry((modbus, Section(path=("other",), schema={}, tag_keys={"modbus": {}})))
    with pytest.raises(RegistryError, match="inside another owner's section"):
        schema.check_registry((Section(path=("fleet",), schema={}), Section(path=("fleet", "x"), schema={})))
    with pytest.raises(RegistryError, match="belongs to the core"):
        schema.build_schema((Section(path=("tags",), schema={}),))
    with pytest.raises(RegistryError, match="belonging to the core: unit"):
        schema.build_schema((Section(path=("x",), schema={}, tag_keys={"unit": {}}),))


def test_an_owner_adds_tags_to_the_runtime_like_the_system_tags(with_notebook, tmp_path: Path, capsys) -> None:
    from softplc.adapters.modbus.address_map import Table, build_address_map
    from softplc.adapters.modbus.settings import ModbusSettings
    from softplc.app.runtime import Runtime
    from softplc.core.clock import SimClock

    path = tmp_path / "plant.yaml"
    path.write_text("version: 1\ntags: {level: {type: float32}}\nnotebook: {database: h.sqlite}\nservers: {modbus: {}}\n")
    config = load_config(path)
    assert [tag.name for tag in config.contributed_tags] == ["_sys.notebook.rows"]
    runtime = Runtime(config, SimClock(), state_dir=tmp_path / "state")
    assert runtime.db.value("_sys.notebook.rows") == 0 and not runtime.db.writable("_sys.notebook.rows", Role.ENGINEER)
    served = build_address_map(config, ModbusSettings.from_servers(config.servers))
    assert "_sys.notebook.rows" in {mapping.name for table in Table for mapping in served.in_table(table)}
    assert main(["tags", str(path), "--format", "json"]) == 0
    assert "_sys.notebook.rows" in {row["name"] for row in json.loads(capsys.readouterr().out)}


def test_an_owner_adds_alarms_that_sit_beside_the_users(with_notebook, tmp_path: Path) -> None:
    from softplc.adapters.alarms.settings import AlarmSettings, configured

    config = load_config(write(tmp_path, "version: 1\nnotebook: {}\ntags:\n  a: {type: float32}\n"))
    assert configured(config)  # no alarms: section, yet the plant has an alarm
    assert [d.name for d in AlarmSettings.from_config(config).definitions] == ["notebook_full"]
    clash = write(tmp_path, """\
        version: 1
        notebook: {}
        tags:
          a: {type: float32}
        alarms:
          definitions:
            - {name: notebook_full, limit: {tag: a, hi: 5}}
        """)
    with pytest.raises(ConfigError) as caught:
        load_config(clash)
    [problem] = caught.value.problems
    assert str(problem).startswith(f"{clash}:2:") and "duplicate alarm name 'notebook_full'" in str(problem)
