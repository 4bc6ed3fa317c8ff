"""Modbus TCP server adapter: the address map derived from tagdb.yaml, and the server itself.

`softplc run` starts it from `servers.modbus`; `softplc modbus-map` prints the map.
The core never imports this package.
"""

from softplc.adapters.modbus.address_map import AddressMap, Mapping, Table, build_address_map
from softplc.adapters.modbus.settings import ModbusSettings

__all__ = ["AddressMap", "Mapping", "ModbusSettings", "Table", "build_address_map"]
