"""The historian's part of tagdb.yaml: the `history:` section and the `history:` key of tags and templates.

    history:                      # where history is kept and the rules for many tags at once
      record: [{tags: "r*_xpos", deadband: 0.01}]
    tags:
      level: {type: float32, min: 0, max: 100, history: {deadband: 1%}}   # one tag's own rule
    templates:
      robot: {history: true, tags: {...}}                                 # every tag of a template

A tag's own key (or its template's) is one more recording rule naming that tag exactly, applied
after the section's pattern rules (`HistorySettings.from_config(config, tag_rules(config))`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from softplc.adapters.history.settings import HISTORY_SCHEMA, RULE_SCHEMA, problems, tag_rule
from softplc.config.schema import Section
from softplc.config.system_tags import runtime_tag_definitions

if TYPE_CHECKING:
    from softplc.adapters.history.settings import Rule
    from softplc.config.plant import PlantConfig
    from softplc.config.yamlsource import Problem

TAG_KEY: dict[str, Any] = {
    "description": "Record this tag's history: true, false, or a rule (deadband, compression) without 'tags'.",
    "anyOf": [
        {"type": "boolean"},
        {**RULE_SCHEMA, "required": [], "properties": {k: v for k, v in RULE_SCHEMA["properties"].items() if k != "tags"}},
    ],
}


def tag_rules(config: PlantConfig) -> list[Rule]:
    """The rules of the tags' own `history:` keys (valid configuration)."""
    return [tag_rule(tag.name, tag.options["history"], config.option_path(tag.name, "history"))
            for tag in config.tags if "history" in tag.options]


def section_problems(config: PlantConfig) -> list[Problem]:
    """The section's problems, and those of the tags' own keys (a bad amount, a percentage without a range)."""
    found = problems(config, [*config.tags, *runtime_tag_definitions(config)]) if config.section("history") is not None else []
    for tag in config.tags:
        spec = tag.options.get("history")
        if not isinstance(spec, Mapping):
            continue
        path = config.option_path(tag.name, "history")
        try:
            rule = tag_rule(tag.name, spec, path)
        except (TypeError, ValueError) as error:
            found.append(config.problem(path, f"history of '{tag.name}': {error}"))
            continue
        for key, deviation in (("deadband", rule.deadband), ("deviation", rule.compression.deviation if rule.compression else None)):
            if deviation is not None and deviation.percent and deviation.resolve(tag) is None:
                where = (*path, "deadband") if key == "deadband" else (*path, "compression", "deviation")
                found.append(config.problem(where, f"{key} {deviation.amount:g}% is a percentage of the tag's range, "
                                                   f"but '{tag.name}' has no min and max; give an absolute amount"))
    return found


SECTION = Section(
    path=("history",),
    schema=HISTORY_SCHEMA,
    tag_keys={"history": TAG_KEY},
    template_keys={"history": TAG_KEY},
    problems=section_problems,
)
