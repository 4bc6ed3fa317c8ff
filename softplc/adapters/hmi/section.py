"""The HMI's parts of tagdb.yaml: `servers: hmi:` (where and how it serves) and `hmi:` (the user views)."""

from __future__ import annotations

from softplc.adapters.hmi.settings import HMI_SECTION, HMI_SERVER, settings_problems
from softplc.adapters.hmi.views import view_problems
from softplc.config.schema import Section

SECTIONS = (
    Section(path=("servers", "hmi"), schema=HMI_SERVER, problems=settings_problems),
    # Views are checked even while the HMI is off: a mistake should not wait for the day it is turned on.
    Section(path=("hmi",), schema=HMI_SECTION, problems=view_problems),
)
