"""Alarms (ISA-18.2): definitions from the `alarms:` section, the engine, the journal (docs/alarms.md).

Adapters (OPC UA, HMI, CLI) never import the engine: they call the `alarms.*` commands
(`plant.commands`) and subscribe to `alarm` events (`plant.events`); what they may import
is the plain data model, `softplc.adapters.alarms.model`.
"""

from typing import TYPE_CHECKING

from softplc.util.lazy import lazy_exports

if TYPE_CHECKING:
    from softplc.adapters.alarms.model import AlarmSnapshot, AlarmState, Priority, Transition

# Imported on first use: softplc.config.schema imports softplc.adapters.alarms.schema, so this package loads
# with every configuration and must stay light.
_MODULES = {"softplc.adapters.alarms.model": ("AlarmSnapshot", "AlarmState", "Priority", "Transition")}
__getattr__, __dir__ = lazy_exports(__name__, _MODULES)

__all__ = ["AlarmSnapshot", "AlarmState", "Priority", "Transition"]
