"""The supervisory pages: alarms, the alarm journal and trends, in the HMI of a runtime that has them.

They are pages like any other module's (`shell.py`), added when the server starts if the runtime
has the commands behind them: the alarm banner (on every page), the alarm summary and the
journal when the `alarms:` section is there (`alarms.*` commands), the trend page when the
historian records (`history.*` commands). Every action and query of these pages goes through
the commands door (command_door.py); alarm changes come over the live channel (alarm_feed.py).

The trend page draws with uPlot, pinned in `hmi/package.json` and installed by `npm ci` into
`hmi/node_modules` (served under /vendor/; `pip install .` ships it when it was installed
before the build). Without it the runtime says so when it starts, and so does the page.
"""

from __future__ import annotations

import logging
from pathlib import Path

from softplc.adapters.hmi.shell import Page, Shell
from softplc.core.commands import Commands

log = logging.getLogger(__name__)

ALARM_BANNER = "/static/js/banners/alarms.js"
PAIR_BANNER = "/static/js/banners/pair.js"  # a member of a redundant pair (docs/redundancy.md)
UPLOT = Path("node_modules") / "uplot" / "dist" / "uPlot.esm.js"


def supervisory_pages(commands: Commands) -> list[Page]:
    """The pages the runtime's commands make possible."""
    pages = []
    if "alarms.list" in commands:
        pages.append(Page("alarms", "Alarms", "/static/js/pages/alarms.js", order=30))
    if "alarms.journal" in commands:
        pages.append(Page("journal", "Journal", "/static/js/pages/journal.js", order=32))
    if "history.plot" in commands:
        pages.append(Page("trends", "Trends", "/static/js/pages/trends.js", order=40))
    return pages


def add_supervisory(shell: Shell, commands: Commands, assets: Path) -> None:
    """Add the pages and the alarm banner; warn when the trend library is missing."""
    for page in supervisory_pages(commands):
        shell.add_page(page)
    if "alarms.summary" in commands:
        shell.banners.insert(0, ALARM_BANNER)  # first under the header: what is wrong now
    if "redundancy.status" in commands:
        shell.banners.insert(0, PAIR_BANNER)  # which runtime of the pair this is, and where the active is
    if "history.plot" in commands and not (assets / UPLOT).is_file():
        log.warning("HMI: the trend library uPlot is missing (%s): the trend page cannot draw; run scripts/bootstrap.sh "
                    "(npm ci in hmi/), or reinstall softplc from a clone where it ran", assets / UPLOT)
