"""softplc: a PLC-style soft controller with OPC UA, Modbus TCP and mobile robots."""

from softplc.core.clock import Clock, RealClock, SimClock
from softplc.core.datatypes import DataType
from softplc.core.function_blocks import CTD, CTU, F_TRIG, R_TRIG, TOF, TON, TP
from softplc.core.program import InOut, Input, Output, Param, Program
from softplc.core.tags import Access, Quality, TagDef

__version__ = "0.1.0"

__all__ = [
    "Access", "Clock", "CTD", "CTU", "DataType", "F_TRIG", "InOut", "Input", "Output", "Param",
    "Program", "Quality", "R_TRIG", "RealClock", "SimClock", "TagDef", "TOF", "TON", "TP",
]
