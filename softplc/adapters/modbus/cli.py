"""`softplc modbus-map`: print the Modbus address map an integrator needs."""

from __future__ import annotations

import argparse
import csv
import json
import sys
from typing import Any

from softplc.adapters.modbus.address_map import AddressMap, Mapping, build_address_map
from softplc.adapters.modbus.settings import ModbusSettings
from softplc.config import load_config

COLUMNS = ("tag", "table", "address", "number", "reference", "type", "encoding", "words", "scale", "word_order", "access", "unit")


def add_commands(subparsers: Any) -> None:
    """Register `modbus-map` with the softplc command line."""
    parser = subparsers.add_parser(
        "modbus-map",
        help="print the Modbus TCP address map",
        description="Print where each tag is served over Modbus TCP: its table, its 0-based protocol "
        "address, its 1-based number (mbpoll -r, most SCADA dialogs), the classic reference "
        "(40001-style), type, register encoding, words, scale, access and unit.",
        epilog="Examples: softplc modbus-map | softplc modbus-map --format csv > map.csv | "
        "softplc modbus-map --table holding",
    )
    parser.add_argument("config", nargs="?", default="tagdb.yaml", help="plant configuration (default tagdb.yaml)")
    parser.add_argument("--format", choices=("table", "csv", "json"), default="table")
    parser.add_argument("--table", choices=("coil", "discrete_input", "holding", "input"), help="only this table")
    parser.add_argument("--no-system", action="store_true", help="leave out the _sys. tags")
    parser.set_defaults(func=cmd_modbus_map)


def rows(address_map: AddressMap, *, table: str | None = None, system: bool = True) -> list[dict[str, Any]]:
    """The map as plain rows (table, then address order)."""
    order = {"coil": 0, "discrete_input": 1, "input": 2, "holding": 3}
    selected = [m for m in address_map.mappings if (table is None or m.table.value == table) and (system or not m.name.startswith("_sys."))]
    selected.sort(key=lambda m: (order[m.table.value], m.address))
    return [_row(mapping) for mapping in selected]


def _row(mapping: Mapping) -> dict[str, Any]:
    codec = mapping.codec
    return {
        "tag": mapping.name,
        "table": mapping.table.value,
        "address": mapping.address,
        "number": mapping.number,
        "reference": mapping.reference,
        "type": mapping.tag.type.value,
        "encoding": mapping.encoding,
        "words": mapping.words,
        "scale": codec.scale if codec is not None and codec.scale is not None else None,
        "word_order": codec.word_order if codec is not None and codec.words > 1 and codec.register_type is not None else None,
        "access": mapping.tag.access.value,
        "unit": mapping.tag.unit,
    }


def cmd_modbus_map(args: argparse.Namespace) -> int:
    config = load_config(args.config)
    settings = ModbusSettings.from_servers(config.servers)
    address_map = build_address_map(config, settings)
    listing = rows(address_map, table=args.table, system=not args.no_system)
    if args.format == "json":
        document = {
            "unit_id": settings.unit_id,
            "host": settings.host,
            "port": settings.port,
            "word_order": settings.word_order,
            "enabled": settings.enabled,
            "tags": listing,
        }
        print(json.dumps(document, indent=2))
    elif args.format == "csv":
        writer = csv.DictWriter(sys.stdout, fieldnames=list(COLUMNS))
        writer.writeheader()
        writer.writerows(listing)
    else:
        from softplc.util.console import print_table

        state = "" if settings.enabled else " (servers.modbus is not enabled: softplc run will not serve it)"
        print(f"Modbus TCP {settings.host}:{settings.port} unit {settings.unit_id}, word order {settings.word_order}{state}")
        print_table([[("" if row[c] is None else str(row[c])) for c in COLUMNS] for row in listing], COLUMNS)
    return 0
