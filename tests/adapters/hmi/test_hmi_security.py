"""The front-end never turns data into markup or code, and the page's policy allows neither.

Configuration strings (tag descriptions, units, plant names, SVG drawings) reach the page as
text only; the browser tests show a `<script>` description as text, this makes sure no module
has a way around it.
"""

from __future__ import annotations

import re

from hmi_support import REPO

from softplc.adapters.hmi.security import CONTENT_SECURITY_POLICY

FORBIDDEN = {
    "innerHTML": "markup from a string",
    "outerHTML": "markup from a string",
    "insertAdjacentHTML": "markup from a string",
    "document.write": "markup from a string",
    "eval(": "code from a string",
    "new Function": "code from a string",
    "setAttribute('style'": "an inline style (refused by the policy)",
    "javascript:": "a javascript: URL",
}


def test_no_front_end_module_builds_markup_or_code_from_strings() -> None:
    offenders = []
    for path in sorted((REPO / "hmi" / "js").rglob("*.js")):
        code = "\n".join(line for line in path.read_text().splitlines() if not line.lstrip().startswith("//"))
        for needle, why in FORBIDDEN.items():
            if needle in code:
                offenders.append(f"{path.relative_to(REPO)}: {needle} ({why})")
    assert not offenders, offenders


def test_the_page_has_no_inline_script_style_or_handler() -> None:
    page = (REPO / "hmi" / "index.html").read_text()
    assert not re.search(r"<script(?![^>]*\bsrc=)[^>]*>", page), "inline <script>"
    assert "<style" not in page and " style=" not in page
    assert not re.search(r"\son[a-z]+\s*=", page), "inline event handler"


def test_the_content_security_policy_allows_no_inline_code() -> None:
    assert "unsafe-inline" not in CONTENT_SECURITY_POLICY and "unsafe-eval" not in CONTENT_SECURITY_POLICY
    for directive in ("default-src 'self'", "script-src 'self'", "style-src 'self'", "object-src 'none'", "frame-ancestors 'none'", "base-uri 'none'"):
        assert directive in CONTENT_SECURITY_POLICY
