"""Tag declarations: plain tags and templates expanded per instance, each checked against its type."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from softplc.config.findings import Findings
from softplc.config.sections import tag_keys, template_keys
from softplc.config.templates import template_instances
from softplc.config.yamlsource import Location
from softplc.core.datatypes import DataType, TypeMismatch
from softplc.core.tags import Access, TagDef
from softplc.util.suggest import did_you_mean


class TagChecker:
    """Builds the plant's tag definitions from `templates:` and `tags:`, recording every problem."""

    def __init__(self, findings: Findings, base_dir: Path) -> None:
        self.findings = findings
        self.base_dir = base_dir
        self.tags: dict[str, TagDef] = {}
        self.tag_paths: dict[str, tuple[Any, ...]] = {}
        self.instances: dict[str, list[str]] = {}  # template → instance names
        self.declared: set[str] = set()  # every tag name declared, valid or not
        self.shared_outputs: set[str] = set()  # tags declared with shared_output: true
        # False when a mistake hides which tags exist (a `tags:` that is not a mapping, a
        # template whose instances cannot be known): then nothing is "missing".
        self.names_known = True

    @property
    def invalid(self) -> set[str]:
        """Tags declared but not defined because their declaration has a (reported) problem."""
        return self.declared - set(self.tags)

    def knows(self, name: str) -> bool:
        """True when `name` is a tag, or may be one whose declaration was already reported."""
        return name in self.tags or name in self.declared or not self.names_known

    def check(self, data: dict[str, Any]) -> None:
        """Templates first (their tags come first in the plant), then plain tags."""
        self._check_templates(data.get("templates"))
        tags = data.get("tags")
        if isinstance(tags, dict):
            for name, spec in tags.items():
                self.add_tag(name, spec, ("tags", name), default_group="")
        elif tags is not None:
            self.names_known = False

    def _check_templates(self, templates: Any) -> None:
        if templates is None:
            return
        if not isinstance(templates, dict):
            self.names_known = False
            return
        findings = self.findings
        for template_name, template in templates.items():
            base = ("templates", template_name)
            if not isinstance(template, dict) or not isinstance(template.get("tags"), dict):
                self.names_known = False
                self.instances.setdefault(template_name, [])
                continue
            found = template_instances(findings, self.base_dir, template_name, template, base)
            self.names_known &= found.complete
            instances = self.instances[template_name] = found.names
            findings.instance_counts[template_name] = len(instances)
            tag_specs = template["tags"]
            overrides = template.get("initial") if isinstance(template.get("initial"), dict) else {}
            for instance, values in overrides.items():
                if instance not in instances:
                    if found.complete:
                        findings.problem((*base, "initial", instance), f"'{instance}' is not an instance of template '{template_name}'{did_you_mean(instance, instances)}", at_key=True)
                    continue
                if not isinstance(values, dict):
                    continue
                for tag_name in values:
                    if tag_name not in tag_specs:
                        findings.problem((*base, "initial", instance, tag_name), f"template '{template_name}' has no tag '{tag_name}'{did_you_mean(tag_name, tag_specs)}", at_key=True)
            group_root = template.get("group", template_name.capitalize() + "s")
            template_options = {key: template[key] for key in template_keys() if key in template}
            for instance in instances:
                instance_overrides = overrides.get(instance) if isinstance(overrides.get(instance), dict) else {}
                from_file = found.initials.get(instance, {})
                for tag_name, spec in tag_specs.items():
                    override: tuple[Any, tuple[Any, ...] | Location] | None = None
                    if tag_name in instance_overrides:
                        override = (instance_overrides[tag_name], (*base, "initial", instance, tag_name))
                    elif tag_name in from_file:
                        override = from_file[tag_name]
                    self.add_tag(
                        f"{instance}_{tag_name}",
                        spec,
                        (*base, "tags", tag_name),
                        default_group=f"{group_root}/{instance}",
                        initial_override=override,
                        template_options=template_options,
                        instance=(template_name, instance),
                    )

    def add_tag(
        self,
        name: str,
        spec: Any,
        path: tuple[Any, ...],
        *,
        default_group: str,
        initial_override: tuple[Any, tuple[Any, ...] | Location] | None = None,
        template_options: dict[str, Any] | None = None,
        instance: tuple[str, str] | None = None,
    ) -> None:
        """Check one tag's declaration; add it when it is valid (its problems are recorded otherwise)."""
        if not isinstance(name, str):
            return
        self.declared.add(name)
        if not isinstance(spec, dict):
            return  # the schema reported it
        if spec.get("shared_output") is True:
            self.shared_outputs.add(name)

        def problem(where: tuple[Any, ...] | Location, message: str, *, at_key: bool = False) -> None:
            if isinstance(where, Location):
                self.findings.problem_at(where, message, instance=instance)
            else:
                self.findings.problem(where, message, at_key=at_key, instance=instance)

        if name in self.tags:
            first = self.findings.source.key(self.tag_paths[name])
            problem(path, f"duplicate tag '{name}' (also defined at {first})", at_key=True)
            return
        if name.startswith("_sys"):
            problem(path, f"tag names starting with '_sys' are reserved for system tags: '{name}'", at_key=True)
            return
        try:
            data_type = DataType(spec.get("type"))
        except ValueError:
            return  # the schema already reported the unknown type
        low, high = spec.get("min"), spec.get("max")
        ok = self._bounds_ok(data_type, low, high, path, problem)
        if initial_override is not None:
            initial, initial_path = initial_override
        else:
            initial, initial_path = spec.get("initial", data_type.default), (*path, "initial")
        # Without an `initial` the tag starts at its type's default, which may break min/max.
        hint = "" if initial_override is not None or "initial" in spec else f" (no 'initial' is given, so it starts at {data_type.default}: add one)"
        try:
            initial = data_type.coerce(initial)
        except TypeMismatch as error:
            problem(initial_path, f"initial value of '{name}' is invalid: {error}")
            return
        if data_type.is_numeric and ok:
            if initial != initial and (low is not None or high is not None):
                problem(initial_path, f"initial value of '{name}' is NaN, which is outside the range of a bounded tag")
                return
            if isinstance(low, (int, float)) and initial < low:
                problem(initial_path, f"initial value {initial} of '{name}' is below its min {low}{hint}")
                ok = False
            if isinstance(high, (int, float)) and initial > high:
                problem(initial_path, f"initial value {initial} of '{name}' is above its max {high}{hint}")
                ok = False
        if not ok:
            return
        options = dict(template_options or {})
        for key in tag_keys():
            if key in spec:  # the tag's own value wins over its template's; mappings merge
                own, inherited = spec[key], options.get(key)
                options[key] = {**inherited, **own} if isinstance(own, dict) and isinstance(inherited, dict) else own
        self.tags[name] = TagDef(
            name=name,
            type=data_type,
            initial=initial,
            unit=str(spec.get("unit", "")),
            description=str(spec.get("description", "")),
            access=Access(spec.get("access", "rw")) if spec.get("access", "rw") in ("rw", "ro") else Access.RW,
            min=low if isinstance(low, (int, float)) and not isinstance(low, bool) else None,
            max=high if isinstance(high, (int, float)) and not isinstance(high, bool) else None,
            retain=bool(spec.get("retain", False)),
            group=str(spec.get("group", default_group)),
            options=options,
        )
        self.tag_paths[name] = path

    @staticmethod
    def _bounds_ok(data_type: DataType, low: Any, high: Any, path: tuple[Any, ...], problem: Callable[..., None]) -> bool:
        """min and max fit the type and each other (each mistake recorded)."""
        ok = True
        for bound_name, bound in (("min", low), ("max", high)):
            if not isinstance(bound, (int, float)) or isinstance(bound, bool):
                continue
            if not data_type.is_numeric:
                problem((*path, bound_name), f"'{bound_name}' is only allowed for numeric tags, not {data_type.value}", at_key=True)
                ok = False
            elif bound != bound:
                problem((*path, bound_name), f"{bound_name} must be a number, not NaN")
                ok = False
            else:
                try:
                    data_type.coerce(bound)
                except TypeMismatch as error:
                    problem((*path, bound_name), f"{bound_name} {bound}: {error}")
                    ok = False
        if isinstance(low, (int, float)) and isinstance(high, (int, float)) and low > high:
            problem((*path, "min"), f"min {low} is greater than max {high}")
            ok = False
        return ok
