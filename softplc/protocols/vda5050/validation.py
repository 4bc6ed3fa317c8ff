"""Checking VDA 5050 messages: JSON Schema (softplc.protocols.vda5050.schemas) plus the order rules a schema cannot say.

    document = decode(payload, "state", "2.1")      # a dict, or MessageError saying what is wrong and where
    problems("order", "2.0", order)                  # [] when the order is valid (schema and graph rules)
"""

from __future__ import annotations

import functools
import json
from typing import Any

from softplc.protocols.vda5050.schemas import ORDER_KIND, schema

MAX_SHOWN = 3  # problems named in one MessageError; the rest counted


class MessageError(ValueError):
    """A message that is not valid JSON, or not a valid VDA 5050 message; the text says where and why."""


@functools.cache
def _validator(kind: str, version: str, closed: bool) -> Any:
    """jsonschema's validator: slow (~3 ms a state here), used only to say what is wrong with a message that failed."""
    from jsonschema import Draft7Validator

    return Draft7Validator(schema(kind, version, closed=closed))


@functools.cache
def _check(kind: str, version: str, closed: bool) -> Any:
    """The schema compiled to Python by fastjsonschema (~0.07 ms a state): raises on the first problem."""
    import fastjsonschema

    return fastjsonschema.compile(schema(kind, version, closed=closed))


def _where(path: Any) -> str:
    text = ""
    for part in path:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return text or "(message)"


def _refuse_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a JSON number (VDA 5050 §6.1.4 excludes NaN and infinity)")


def parse_json(payload: bytes | str) -> Any:
    """The JSON value of a payload; MessageError for bytes that are not UTF-8 JSON (NaN and Infinity refused)."""
    try:
        text = payload.decode("utf-8") if isinstance(payload, bytes) else payload
        return json.loads(text, parse_constant=_refuse_constant)
    except UnicodeDecodeError as error:
        raise MessageError(f"not UTF-8: {error.reason} at byte {error.start}") from None
    except json.JSONDecodeError as error:
        raise MessageError(f"not JSON: {error.msg} at line {error.lineno} column {error.colno}") from None
    except (ValueError, RecursionError) as error:
        raise MessageError(f"not JSON: {error}") from None


def problems(kind: str, version: str, document: Any, *, closed: bool = True) -> list[str]:
    """Every problem of a message, 'path: what is wrong' ([] when valid); orders also get the graph rules."""
    import fastjsonschema

    try:
        _check(kind, version, closed)(document)
    except fastjsonschema.JsonSchemaException:
        pass  # wrong somewhere: the slow validator below says where and why, every problem
    else:
        return order_problems(document) if kind == ORDER_KIND else []
    errors = sorted(_validator(kind, version, closed).iter_errors(document), key=lambda error: list(error.absolute_path))
    found = [f"{_where(error.absolute_path)}: {error.message}" for error in errors]
    if not found and kind == ORDER_KIND:
        found = order_problems(document)
    return found


def decode(payload: bytes | str, kind: str, version: str, *, closed: bool = False) -> dict[str, Any]:
    """A vehicle's (or master's) message as a dict, checked against its schema; MessageError otherwise."""
    document = parse_json(payload)
    if not isinstance(document, dict):
        raise MessageError(f"a {kind} message must be a JSON object, not {type(document).__name__}")
    found = problems(kind, version, document, closed=closed)
    if found:
        more = f" (and {len(found) - MAX_SHOWN} more)" if len(found) > MAX_SHOWN else ""
        raise MessageError("; ".join(found[:MAX_SHOWN]) + more)
    return document


def order_problems(order: dict[str, Any]) -> list[str]:
    """The rules of an order's graph (spec 2.1 §6.6.1–6.6.2) that its schema cannot express."""
    nodes, edges = order["nodes"], order["edges"]
    found: list[str] = []
    if not nodes:
        found.append("nodes: an order needs at least one node")
        return found
    if len(edges) != len(nodes) - 1:
        found.append(f"edges: {len(edges)} edges for {len(nodes)} nodes (must be one fewer)")
        return found
    for index, node in enumerate(nodes):
        if node["sequenceId"] % 2:
            found.append(f"nodes[{index}].sequenceId: {node['sequenceId']} is odd (nodes take even sequence ids)")
        if index and node["sequenceId"] != nodes[index - 1]["sequenceId"] + 2:
            found.append(f"nodes[{index}].sequenceId: {node['sequenceId']} does not follow {nodes[index - 1]['sequenceId']}")
    for index, edge in enumerate(edges):
        start, end = nodes[index], nodes[index + 1]
        if edge["sequenceId"] != start["sequenceId"] + 1:
            found.append(f"edges[{index}].sequenceId: {edge['sequenceId']} is not between its nodes' {start['sequenceId']} "
                         f"and {end['sequenceId']}")
        if (edge["startNodeId"], edge["endNodeId"]) != (start["nodeId"], end["nodeId"]):
            found.append(f"edges[{index}]: runs {edge['startNodeId']} → {edge['endNodeId']}, "
                         f"but its nodes are {start['nodeId']} → {end['nodeId']}")
        if edge["released"] and not (start["released"] and end["released"]):
            found.append(f"edges[{index}]: released, but one of its nodes is not")
    released = [element["released"] for pair in zip(nodes, [*edges, None]) for element in pair if element is not None]
    if True in released[released.index(False):] if False in released else False:
        found.append("released nodes or edges follow an unreleased one (the base must come before the horizon)")
    if not nodes[0]["released"]:
        found.append("nodes[0]: the first node must be released")
    return found
