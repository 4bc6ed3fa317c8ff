"""The layers of softplc, and no import cycles: every module can be read, tested and changed from the bottom up.

The graph counts every import statement (at module level, inside functions and under
TYPE_CHECKING: each is a dependency, even when Python would tolerate the cycle at run time)
and the registries that name modules as strings (`COMMAND_MODULES`, the lazy `_MODULES` of
package `__init__`s): a module listed there is imported by the registry's owner. Importing
`a.b.c` also runs `a/__init__` and `a/b/__init__`; those implicit edges are not counted, or
every package would be a cycle with its own modules. Adapters are found by scanning their
folder (softplc/config/manifest.py), which is no import.

The layers (docs/architecture.md), each importing only those below it: utilities ← core ←
configuration ← engine ← adapters ← application. Security, storage, protocols and robotics are
libraries the adapters (and the clients) use. No adapter imports another adapter, the engine or
the application: it is handed the plant API (softplc/core/plant.py). The clients (command-line
tools that talk to a running plant) import no adapter, engine or application module.
"""

from __future__ import annotations

import ast
from pathlib import Path

from conftest import REPO

PACKAGE = REPO / "softplc"


def module_files() -> dict[str, tuple[Path, bool]]:
    """Module name → (file, is a package)."""
    modules = {}
    for file in PACKAGE.rglob("*.py"):
        parts = list(file.relative_to(REPO).with_suffix("").parts)
        is_package = parts[-1] == "__init__"
        modules[".".join(parts[:-1] if is_package else parts)] = (file, is_package)
    return modules


def import_graph() -> dict[str, set[str]]:
    """softplc module → the softplc modules it imports (see the module docstring)."""
    modules = module_files()
    graph: dict[str, set[str]] = {}
    for name, (file, is_package) in modules.items():
        edges: set[str] = set()
        for node in ast.walk(ast.parse(file.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                edges.update(alias.name for alias in node.names)
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:  # relative: from the package of this module
                    package = name.split(".") if is_package else name.split(".")[:-1]
                    base = ".".join(package[: len(package) - node.level + 1] + ([base] if base else []))
                edges.add(base)
                edges.update(f"{base}.{alias.name}" for alias in node.names)  # `from pkg import module`
            elif isinstance(node, (ast.Assign, ast.AnnAssign)) and node.value is not None:
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                if any(isinstance(target, ast.Name) and target.id.endswith("_MODULES") for target in targets):
                    edges.update(c.value for c in ast.walk(node.value) if isinstance(c, ast.Constant) and isinstance(c.value, str))
        graph[name] = {edge for edge in edges if edge in modules and edge != name}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for target in sorted(graph[node]):
            if target not in index:
                visit(target)
                low[node] = min(low[node], low[target])
            elif target in on_stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def test_no_import_cycle_inside_softplc() -> None:
    graph = import_graph()
    found = cycles(graph)
    explained = ["\n".join(f"  {m} -> {', '.join(sorted(graph[m] & set(cycle)))}" for m in cycle) for cycle in found]
    assert not found, "import cycles:\n" + "\n\n".join(explained)


def test_the_graph_sees_every_kind_of_import() -> None:
    graph = import_graph()
    assert "softplc.config.plant" in graph["softplc.config.sections"]  # under TYPE_CHECKING
    assert "softplc.latency.client_process" in graph["softplc.latency.measurement"]  # inside a function
    assert "softplc.clients.tags.cli" in graph["softplc.app.cli"]  # COMMAND_MODULES
    assert "softplc.adapters.metrics.adapter" in graph["softplc.adapters.metrics.manifest"]  # inside a function
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_command_modules_print_tables_without_the_top_level_cli() -> None:
    graph = import_graph()
    # softplc.app.entry_point is the process around the command line (the console script), not a command module.
    assert [name for name, targets in graph.items() if "softplc.app.cli" in targets] == ["softplc.app.entry_point"]


# What each part of the package may import besides itself (its own package: always).
_BELOW_ADAPTERS = {"util", "core", "config", "security", "storage", "protocols", "robotics"}
MAY_IMPORT: dict[str, set[str]] = {
    "util": set(),
    "core": {"util"},
    "config": {"util", "core"},
    "security": {"util", "core", "config"},
    "engine": {"util", "core", "config"},
    "storage": {"util", "core", "config"},
    "protocols": {"util", "core", "config", "security"},
    "robotics": {"util", "core", "config"},
    "adapters": _BELOW_ADAPTERS,  # and its own adapter's folder (see part_of)
    "clients": _BELOW_ADAPTERS,
}


def part_of(module: str) -> str:
    """The layer part a module belongs to: 'core', 'engine', 'adapters.hmi', 'app', 'latency'..."""
    parts = module.split(".")
    if len(parts) == 1 or parts[1] in ("__main__",):
        return "package"
    if parts[1] == "adapters" and len(parts) > 2:
        return f"adapters.{parts[2]}"
    return parts[1]


def layer_violations(graph: dict[str, set[str]]) -> list[str]:
    """Every import that goes against the layers, as 'importer -> imported (why)'."""
    found = []
    for module, targets in sorted(graph.items()):
        part = part_of(module)
        layer = part.split(".")[0]
        if layer not in MAY_IMPORT:
            continue  # the application, the thesis tools, the package's face: anything below them
        allowed = MAY_IMPORT[layer] | {part}
        for target in sorted(targets):
            target_part = part_of(target)
            if target_part in allowed or target_part.split(".")[0] in allowed - {"adapters"}:
                continue
            if target == "softplc.adapters":  # the folder's package: a docstring, no code
                continue
            if target == "softplc" and layer not in ("util", "core"):  # the package's face: __version__ (it imports the core)
                continue
            found.append(f"{module} -> {target} ({part} may import {', '.join(sorted(allowed))})")
    return found


def test_every_import_respects_the_layers() -> None:
    found = layer_violations(import_graph())
    assert not found, "imports against the layers (docs/architecture.md):\n" + "\n".join(found)


def test_the_layer_check_fails_on_an_adapter_that_imports_the_runtime_or_another_adapter() -> None:
    graph = {
        "softplc.adapters.hmi.server": {"softplc.app.runtime", "softplc.adapters.alarms.engine", "softplc.core.plant",
                                        "softplc.adapters.hmi.live"},
        "softplc.clients.tags.cli": {"softplc.adapters.opcua.server"},
        "softplc.core.tagdb": {"softplc.engine.scan"},
        "softplc.app.runtime": {"softplc.adapters.hmi.server"},
    }
    found = layer_violations(graph)
    assert [line.split(" (")[0] for line in found] == [
        "softplc.adapters.hmi.server -> softplc.adapters.alarms.engine",
        "softplc.adapters.hmi.server -> softplc.app.runtime",
        "softplc.clients.tags.cli -> softplc.adapters.opcua.server",
        "softplc.core.tagdb -> softplc.engine.scan",
    ]


def test_top_level_modules_are_few() -> None:
    loose = sorted(path.name for path in PACKAGE.glob("*.py"))
    assert loose == ["__init__.py", "__main__.py"], loose
