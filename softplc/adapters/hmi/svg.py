"""Reading a user's SVG drawing: which element ids it has, and of which element type.

The drawing comes from the plant's own configuration (an engineer's file, e.g. from Inkscape),
but it is parsed defensively all the same: a size limit, no external entities (ElementTree never
fetches them) and expat's protection against entity expansion bombs. The browser never inserts
it as markup: the page parses it, drops scripts, event handlers and foreign content, and turns
`style` attributes into presentation attributes (a strict Content-Security-Policy forbids inline
styles), see hmi/js/svg.js.
"""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree
from pathlib import Path

MAX_SVG_BYTES = 20 * 1024 * 1024


class SvgError(ValueError):
    """The file is not a readable SVG drawing."""


def svg_ids(path: Path) -> dict[str, str]:
    """{element id: element name without namespace ('rect', 'text', 'g'...)} of an SVG file."""
    try:
        size = path.stat().st_size
    except OSError as error:
        raise SvgError(f"cannot read {path}: {error.strerror or error}") from None
    if size > MAX_SVG_BYTES:
        raise SvgError(f"{path} is {size / 1e6:.0f} MB; an SVG view may have at most {MAX_SVG_BYTES // 1_000_000} MB")
    ids: dict[str, str] = {}
    root_seen = False
    try:
        for _, element in ElementTree.iterparse(path, events=("start",)):
            name = element.tag.rsplit("}", 1)[-1]
            if not root_seen:
                root_seen = True
                if name != "svg":
                    raise SvgError(f"{path} is not an SVG drawing (its root element is <{name}>)")
            identifier = element.get("id")
            if identifier is not None:
                ids.setdefault(identifier, name)
    except ElementTree.ParseError as error:
        reason = str(error).split(":")[0]  # "mismatched tag: line 1, column 10"
        line, column = error.position
        raise SvgError(f"{path} is not well-formed XML: {reason} at line {line}, column {column + 1}") from None
    if not root_seen:
        raise SvgError(f"{path} is empty")
    return ids
