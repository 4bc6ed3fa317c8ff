"""softplc: a PLC-style soft controller with OPC UA, Modbus TCP and mobile robots."""

from typing import TYPE_CHECKING

from softplc.util.lazy import lazy_exports

if TYPE_CHECKING:
    from softplc.core.clock import Clock, RealClock, SimClock
    from softplc.core.datatypes import DataType
    from softplc.core.function_blocks import CTD, CTU, F_TRIG, R_TRIG, TOF, TON, TP
    from softplc.core.program import InOut, Input, Output, Param, Program
    from softplc.core.tags import Access, Quality, TagDef

__version__ = "0.1.0"

# Public names and their modules, imported on first use (PEP 562): the `softplc` command starts
# with `import softplc`, and a Ctrl-C is only answered cleanly once the command's own code runs
# (softplc/app/entry_point.py), so nothing heavy may load before it.
_MODULES = {
    "softplc.core.clock": ("Clock", "RealClock", "SimClock"),
    "softplc.core.datatypes": ("DataType",),
    "softplc.core.function_blocks": ("CTD", "CTU", "F_TRIG", "R_TRIG", "TOF", "TON", "TP"),
    "softplc.core.program": ("InOut", "Input", "Output", "Param", "Program"),
    "softplc.core.tags": ("Access", "Quality", "TagDef"),
}
__getattr__, __dir__ = lazy_exports(__name__, _MODULES)

__all__ = [
    "Access", "Clock", "CTD", "CTU", "DataType", "F_TRIG", "InOut", "Input", "Output", "Param",
    "Program", "Quality", "R_TRIG", "RealClock", "SimClock", "TagDef", "TOF", "TON", "TP",
]
