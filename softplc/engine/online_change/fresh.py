"""Program modules loaded fresh from their source (an online change), and where a module's source is.

`importlib.import_module` answers from `sys.modules`, and `importlib.reload` changes the running
module in place (a half-applied change if the new code fails). An online change therefore
compiles each program module's current source text into a new module object — never from
`__pycache__`, whose timestamps can miss an edit made within the same second — while the running
module stays untouched; `install()` puts the new modules in `sys.modules` once the change is
swapped in. Only the modules named in `program:` are loaded fresh: a helper module they import
comes from the module cache as usual (changing one needs a restart of the runtime).
"""

from __future__ import annotations

import hashlib
import importlib.util
import sys
from pathlib import Path
from types import ModuleType

from softplc.config.programs import importable

USER_PREFIX = "softplc_user_"  # the module name of a program loaded from `file.py:Class`


def module_file(module_name: str, base_dir: Path) -> Path | None:
    """The source file a program module is (or would be) loaded from; None for a module without one."""
    if module_name.endswith(".py"):
        return (base_dir / module_name).resolve()
    importable(base_dir)
    try:
        spec = importlib.util.find_spec(module_name)
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.has_location or spec.origin is None or not spec.origin.endswith(".py"):
        return None
    return Path(spec.origin)


def source_digest(file: Path | None) -> str:
    """A digest of a source file's text ('' when there is none or it cannot be read)."""
    if file is None:
        return ""
    try:
        return hashlib.sha256(file.read_bytes()).hexdigest()
    except OSError:
        return ""


class FreshModules:
    """A `load_module` for `load_config`: each program module compiled anew from its source, once per change."""

    def __init__(self) -> None:
        self.modules: dict[str, ModuleType] = {}  # module name as configured → the fresh module
        self.digests: dict[str, str] = {}  # module name as configured → digest of the source compiled
        self._failed: dict[str, BaseException] = {}

    def __call__(self, module_name: str, base_dir: Path) -> ModuleType:
        # Each module runs once per change: two programs of one module share its classes (or its error).
        if module_name in self.modules:
            return self.modules[module_name]
        if module_name in self._failed:
            raise self._failed[module_name]
        try:
            return self._load(module_name, base_dir)
        except BaseException as error:
            self._failed[module_name] = error
            raise

    def _load(self, module_name: str, base_dir: Path) -> ModuleType:
        file = module_file(module_name, base_dir)
        if module_name.endswith(".py"):
            if file is None or not file.exists():
                raise ImportError(f"no such file {file}")
            spec = importlib.util.spec_from_file_location(f"{USER_PREFIX}{file.stem}", file)
        elif file is None:
            if importlib.util.find_spec(module_name) is None:
                raise ModuleNotFoundError(f"No module named '{module_name}'", name=module_name)
            # A compiled or built-in module: it cannot be reloaded from source; use it as it is.
            module = importlib.import_module(module_name)
            self.modules[module_name] = module
            return module
        else:
            spec = importlib.util.spec_from_file_location(module_name, file)
        if spec is None:
            raise ImportError(f"cannot load {file}")
        source = file.read_bytes()
        module = importlib.util.module_from_spec(spec)
        code = compile(importlib.util.decode_source(source), str(file), "exec", dont_inherit=True)
        name = spec.name
        # While it runs, the module is the one its name imports (as in a normal import: dataclasses
        # and typing look it up there); the running one is put back whatever happens.
        previous = sys.modules.get(name)
        sys.modules[name] = module
        try:
            exec(code, module.__dict__)
        finally:
            if previous is not None:
                sys.modules[name] = previous
            else:
                sys.modules.pop(name, None)
        self.modules[module_name] = module
        self.digests[module_name] = hashlib.sha256(source).hexdigest()
        return module

    def install(self, names: set[str]) -> None:
        """Make these fresh modules the ones `import` finds from now on (once the change is swapped in)."""
        for configured in names:
            module = self.modules.get(configured)
            if module is None or module.__name__.startswith(USER_PREFIX):
                continue
            sys.modules[module.__name__] = module
            parent, _, child = module.__name__.rpartition(".")
            if parent in sys.modules:  # `import programs.x` binds programs.x too
                setattr(sys.modules[parent], child, module)
