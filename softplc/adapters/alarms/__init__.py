"""Alarms (ISA-18.2): definitions from the `alarms:` section, the engine, the journal (docs/alarms.md).

Other adapters (OPC UA, HMI) and the CLI never import this package: they call the `alarms.*`
commands (`plant.commands`) and subscribe to `alarm` events (`plant.events`); the plain data model
they share with it is the core's, `softplc.core.alarms`.
"""

from typing import TYPE_CHECKING

from softplc.util.lazy import lazy_exports

if TYPE_CHECKING:
    from softplc.core.alarms import AlarmSnapshot, AlarmState, Priority, Transition

# Imported on first use: softplc.config.schema imports softplc.adapters.alarms.schema, so this package loads
# with every configuration and must stay light.
_MODULES = {"softplc.core.alarms": ("AlarmSnapshot", "AlarmState", "Priority", "Transition")}
__getattr__, __dir__ = lazy_exports(__name__, _MODULES)

__all__ = ["AlarmSnapshot", "AlarmState", "Priority", "Transition"]
