"""The page shell: which pages the navigation lists, what the banner slot shows, and extra routes.

The browser builds its navigation from `GET /api/session` (`pages`), loads a page's ES module
when it is opened (`module`, with the page's `params`), and loads every `banners` module into
the slot under the header on every page. The HMI's own modules add what the plant has when it
starts (supervisory.py: alarms, journal and trends when their commands exist; operations.py):

    shell.add_page(Page("trends", "Trends", "/static/js/pages/trends.js", order=40))
    shell.add_banner("/static/js/banners/alarms.js")      # e.g. the alarm banner
    shell.add_routes([web.get("/api/audit.csv", handler)])   # e.g. the audit export

A page module exports `mount(root, context)` and returns a function that unmounts it
(hmi/js/pages/*.js are examples; docs/hmi.md describes `context`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from aiohttp import web

from softplc.core.roles import Role

_RANK = {Role.VIEWER: 0, Role.OPERATOR: 1, Role.ENGINEER: 2}


@dataclass(frozen=True)
class Page:
    """One entry of the navigation: `#/ID` opens `module` with `params`."""

    id: str
    title: str
    module: str
    order: int = 100
    group: str = ""  # pages of one group are listed together (e.g. "Views")
    min_role: Role = Role.VIEWER  # hidden from lesser roles (the API still checks every request)
    params: dict[str, Any] = field(default_factory=dict)

    def describe(self) -> dict[str, Any]:
        return {"id": self.id, "title": self.title, "module": self.module, "group": self.group, "params": self.params}


@dataclass
class Shell:
    """Pages, banners and routes of the HMI; frozen once the server has started."""

    pages: list[Page] = field(default_factory=list)
    banners: list[str] = field(default_factory=list)
    routes: list[web.AbstractRouteDef] = field(default_factory=list)
    started: bool = False

    def add_page(self, page: Page) -> None:
        self._check()
        if any(existing.id == page.id for existing in self.pages):
            raise ValueError(f"the HMI already has a page '{page.id}'")
        self.pages.append(page)

    def add_banner(self, module: str) -> None:
        self._check()
        self.banners.append(module)

    def add_routes(self, routes: list[web.AbstractRouteDef]) -> None:
        self._check()
        self.routes.extend(routes)

    def navigation(self, role: Role) -> list[dict[str, Any]]:
        """The pages `role` sees, in order."""
        visible = [page for page in self.pages if _RANK[role] >= _RANK[page.min_role]]
        return [page.describe() for page in sorted(visible, key=lambda page: (page.order, page.title))]

    def _check(self) -> None:
        if self.started:
            raise RuntimeError("the HMI has started: add pages, banners and routes before runtime.start()")


def builtin_pages(has_fleet: bool, views: list[tuple[str, str]]) -> list[Page]:
    """The pages every plant has, plus one per user view and the robots page when there is a fleet."""
    pages = [
        Page("overview", "Overview", "/static/js/pages/overview.js", order=10),
        Page("tags", "Tags", "/static/js/pages/tags.js", order=60),
        Page("tasks", "Tasks", "/static/js/pages/tasks.js", order=70),
    ]
    if has_fleet:
        pages.append(Page("robots", "Robots", "/static/js/pages/robots.js", order=80))
    for index, (name, title) in enumerate(views):
        pages.append(Page(f"view/{name}", title, "/static/js/pages/view.js", order=20 + index, group="Views", params={"view": name}))
    return pages
