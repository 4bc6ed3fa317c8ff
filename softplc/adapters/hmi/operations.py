"""Operating the plant from the HMI (issue 17): forcing, program control, online change, the audit trail.

Added to the HMI's shell like any other module's pages (softplc/adapters/hmi/shell.py):

- the pages call commands through the HMI's commands door (`/api/commands`, command_door.py);
- the **Forced** page (every role: what is forced, since when, by whom; engineers unforce there)
  and a banner on every page while anything is forced ("3 tags forced"), linking to it;
- the **Audit** page (engineers: the audit trail with filters) and its CSV export (audit_export.py).

Forcing controls in a tag's details and program control on the Tasks page are front-end modules
(hmi/js/ops/) that these pages and the banner load; the forced mark travels with the live values.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from softplc.adapters.hmi.audit_export import audit_routes
from softplc.adapters.hmi.shell import Page
from softplc.core.roles import Role

if TYPE_CHECKING:
    from softplc.adapters.hmi.api import HmiServer

FORCED_BANNER = "/static/js/ops/forced-banner.js"


def install_operations(server: HmiServer) -> None:
    """Add the operations pages, the forced banner and their routes to the server's shell (before it starts)."""
    shell = server.shell
    shell.add_page(Page("forced", "Forced", "/static/js/pages/forced.js", order=75))
    shell.add_page(Page("audit", "Audit", "/static/js/pages/audit.js", order=90, min_role=Role.ENGINEER))
    shell.add_banner(FORCED_BANNER)
    shell.add_routes(audit_routes(server))
