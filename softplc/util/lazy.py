"""Lazy re-exports for a package's `__init__` (PEP 562): public names load their module on first use.

`softplc --help` imports the command modules of every package and must not load asyncua, scipy
or pymodbus with them, yet `from softplc.adapters.opcua import OpcUaServer` should keep working.

    __getattr__, __dir__ = lazy_exports(__name__, {"softplc.adapters.opcua.server": ("OpcUaServer",), ...})
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping, Sequence
from typing import Any


def lazy_exports(package: str, modules: Mapping[str, Sequence[str]]) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """A module `__getattr__` and `__dir__` that import each name's module when it is first asked for."""
    exports = {name: module for module, names in modules.items() for name in names}

    def __getattr__(name: str) -> Any:
        if name not in exports:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(exports[name]), name)
        setattr(sys.modules[package], name, value)  # the next lookup does not come here
        return value

    def __dir__() -> list[str]:
        return sorted([*vars(sys.modules[package]), *exports])

    return __getattr__, __dir__
