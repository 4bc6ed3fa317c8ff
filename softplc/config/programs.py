"""A program of a task: its class imported from `module:Class`, its variables bound, its parameters converted."""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import sys
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

from softplc.config.findings import Findings
from softplc.config.plant import SYSTEM_PREFIX
from softplc.config.tags import TagChecker
from softplc.core.program import Program
from softplc.util.suggest import did_you_mean


@dataclass(frozen=True)
class Write:
    """A program's Output or InOut variable bound to a tag, and where that binding is written."""

    tag: str
    program: str
    variable: str
    path: tuple[Any, ...]
    instance: tuple[str, str] | None = None  # (template, instance) of a `for_each` program


class ProgramChecker:
    """Checks the `program:`, `bind:` and `params:` of the programs of every task."""

    def __init__(self, findings: Findings, tags: TagChecker, base_dir: Path, load_module: ModuleLoader | None = None) -> None:
        self.findings = findings
        self.tags = tags
        self.base_dir = base_dir
        self.load_module = load_module

    def import_class(self, reference: str, path: tuple[Any, ...]) -> type[Program] | None:
        try:
            return import_program(reference, self.base_dir, self.load_module)
        except ImportError as error:
            self.findings.problem(path, str(error))
            return None

    def bindings(
        self, cls: type[Program] | None, bind: Any, substitution: dict[str, str], path: tuple[Any, ...], name: str,
        instance: tuple[str, str] | None = None,
    ) -> tuple[dict[str, str | list[str]] | None, list[Write]]:
        """The variable → tag(s) map of one program instance (None if wrong), and the tags it writes."""
        if not isinstance(bind, dict):
            return None, []
        findings = self.findings
        ok = True
        bindings: dict[str, str | list[str]] = {}
        writes: list[Write] = []
        variables = cls.variables if cls is not None else {}
        for var, target in bind.items():
            var_path = (*path, "bind", var)
            if cls is not None and var not in variables:
                known = ", ".join(variables) or "none"
                findings.problem(var_path, f"program {cls.__name__} has no variable '{var}'{did_you_mean(var, variables)}; its variables: {known}",
                                 at_key=True, instance=instance)
                ok = False
                continue
            targets = [target] if isinstance(target, str) else target if isinstance(target, list) else []
            resolved = []
            for index, tag in enumerate(targets):
                if not isinstance(tag, str):
                    continue
                tag = substitute(tag, substitution)
                where = var_path if isinstance(target, str) else (*var_path, index)
                if tag.startswith(SYSTEM_PREFIX):
                    findings.problem(where, f"'{var}' of program '{name}' is bound to the system tag '{tag}': programs bind plant tags only "
                                     "(system tags are read by clients, --until and the HMI)", instance=instance)
                    ok = False
                elif tag not in self.tags.tags:
                    # A tag declared with a mistake was reported where it is declared: say nothing more here.
                    if not self.tags.knows(tag):
                        findings.problem(where, f"'{var}' of program '{name}' is bound to a missing tag '{tag}'{did_you_mean(tag, self.tags.tags)}", instance=instance)
                    ok = False
                elif cls is not None and variables[var].direction.writes:
                    writes.append(Write(tag, name, var, where, instance))
                resolved.append(tag)
            bindings[var] = resolved[0] if isinstance(target, str) else resolved
        if cls is not None:
            for var, variable in variables.items():
                if var not in bind and not variable.optional:
                    where = (*path, "bind") if (*path, "bind") in findings.source.keys else path
                    findings.problem(where, f"variable '{var}' of program '{name}' ({cls.__name__}) is not bound to a tag", at_key=True, instance=instance)
                    ok = False
        return (bindings if ok and cls is not None else None), writes

    def params(
        self, cls: type[Program] | None, params: Any, substitution: dict[str, str], path: tuple[Any, ...], name: str,
        instance: tuple[str, str] | None = None,
    ) -> dict[str, Any] | None:
        """The converted `params:` of one program instance, or None if any is wrong."""
        if cls is None or not isinstance(params, dict):
            return None
        findings = self.findings
        ok = True
        result: dict[str, Any] = {}
        for key, value in params.items():
            param = cls.params.get(key)
            if param is None:
                known = ", ".join(cls.params) or "none"
                findings.problem((*path, "params", key), f"program {cls.__name__} has no parameter '{key}'{did_you_mean(key, cls.params)}; its parameters: {known}",
                                 at_key=True, instance=instance)
                ok = False
                continue
            if isinstance(value, str):
                value = substitute(value, substitution)
            try:
                result[key] = param.convert(value)
            except ValueError as error:
                findings.problem((*path, "params", key), f"parameter '{key}' of program '{name}': {error}", instance=instance)
                ok = False
        for key, param in cls.params.items():
            if param.required and key not in params:
                findings.problem(path, f"program '{name}' needs the parameter '{key}' ({param.description or 'no default'})", at_key=True, instance=instance)
                ok = False
        return result if ok else None


def substitute(text: str, substitution: dict[str, str]) -> str:
    """`text` with each {TEMPLATE} placeholder replaced by the instance's name."""
    for key, value in substitution.items():
        text = text.replace("{" + key + "}", value)
    return text


ModuleLoader = Callable[[str, Path], ModuleType]


def split_reference(reference: str) -> tuple[str, str]:
    """(module, class) of `module:Class`, `module.Class` or `file.py:Class`; raise ImportError if neither."""
    if ":" in reference:
        module_name, _, class_name = reference.rpartition(":")
    else:
        module_name, _, class_name = reference.rpartition(".")
    if not module_name or not class_name:
        raise ImportError(f"cannot load program '{reference}': write module:Class, e.g. programs.plant:PlantSimulator")
    return module_name, class_name


def _interruption(error: BaseException) -> BaseException | None:
    """A Ctrl-C (or an exit) that Python wrapped while importing: a KeyboardInterrupt in `__set_name__`
    comes out as "RuntimeError: Error calling __set_name__" on Python 3.11, the interrupt its cause."""
    seen: set[int] = set()
    cause: BaseException | None = error
    while cause is not None and id(cause) not in seen:
        if not isinstance(cause, Exception):
            return cause
        seen.add(id(cause))
        cause = cause.__cause__ or cause.__context__
    return None


def import_program(reference: str, base_dir: Path, load_module: ModuleLoader | None = None) -> type[Program]:
    """Resolve `module:Class`, `module.Class` or `file.py:Class` to a Program subclass.

    `base_dir` (the configuration's folder) is importable, so `programs.x:Y` finds the
    plant's own `programs/` folder. `load_module(name, base_dir)` loads the module (default: the
    usual import, from the module cache; an online change loads fresh ones, `softplc.engine.online_change.fresh`).
    """
    module_name, class_name = split_reference(reference)
    try:
        module = (load_module or cached_module)(module_name, base_dir)
    except ModuleNotFoundError as error:
        missing = error.name or ""
        if module_name == missing or module_name.startswith(missing + "."):
            where = f"{base_dir.resolve()} (the configuration's folder) or the installed packages"
            raise ImportError(f"cannot load program '{reference}': no module named '{missing}' in {where}") from None
        # The program's module exists, but something it imports does not.
        raise ImportError(f"cannot load program '{reference}': module {module_name} imports '{missing}', which is not installed") from None
    except SyntaxError as error:  # IndentationError and TabError too
        raise ImportError(f"cannot load program '{reference}': {syntax_error_at(error)}") from None
    except Exception as error:  # user code may raise anything while importing
        interrupted = _interruption(error)
        if interrupted is not None:
            raise interrupted from None  # a Ctrl-C during the import is the user's, not the module's fault
        raise ImportError(f"cannot load program '{reference}': {type(error).__name__}: {error}{raised_at(error)}") from None
    cls = getattr(module, class_name, None)
    if cls is None:
        names = [n for n, v in vars(module).items() if inspect.isclass(v) and issubclass(v, Program) and v is not Program]
        raise ImportError(f"cannot load program '{reference}': module {module_name} has no class '{class_name}'{did_you_mean(class_name, names)}")
    if not (inspect.isclass(cls) and issubclass(cls, Program)):
        raise ImportError(f"cannot load program '{reference}': {class_name} is not a softplc Program subclass")
    return cls


def cached_module(module_name: str, base_dir: Path) -> ModuleType:
    """The module as Python imports it (from sys.modules when already imported); a `.py` file is loaded anew."""
    if module_name.endswith(".py"):
        file = (base_dir / module_name).resolve()
        spec = importlib.util.spec_from_file_location(f"softplc_user_{file.stem}", file)
        if spec is None or spec.loader is None or not file.exists():
            raise ImportError(f"no such file {file}")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module
    importable(base_dir)
    return importlib.import_module(module_name)


def importable(base_dir: Path) -> None:
    """Make the configuration's folder importable (`programs.x:Y` finds its `programs/`)."""
    base = str(base_dir.resolve())
    if base not in sys.path:
        sys.path.insert(0, base)


def syntax_error_at(error: SyntaxError) -> str:
    """'PATH:LINE:COL: SyntaxError: message' (the whole path, as editors and terminals link it)."""
    where = ""
    if error.filename:
        where = f"{Path(error.filename).resolve()}:{error.lineno or 1}" + (f":{error.offset}" if error.offset else "") + ": "
    return f"{where}{type(error).__name__}: {error.msg}"


def raised_at(error: BaseException) -> str:
    """' at FILE:LINE' of the innermost frame of a traceback (where user code raised), or ''."""
    frames = traceback.extract_tb(error.__traceback__)
    return f" at {frames[-1].filename}:{frames[-1].lineno}" if frames else ""
