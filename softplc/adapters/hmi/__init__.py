"""The web HMI: an adapter that serves the plant to browsers (aiohttp, in the runtime's loop).

    hmi = HmiServer(config, HmiSettings(port=0))
    runtime.add_adapter(hmi); await runtime.start()
    hmi.url                      "http://127.0.0.1:PORT/" (the real port when 0 was asked for)

Modules, one concept each: `settings` (the `servers: hmi:` and `hmi: views:` sections),
`server` (the adapter), `api` (JSON routes under /api/), `live` (the WebSocket hub),
`sessions` (logins, cookies, CSRF), `views` (user mimics), `plant` (the overview's model),
`shell` (pages and routes other modules add). The front-end lives in the top-level `hmi/`
folder (docs/hmi.md).
"""

from typing import TYPE_CHECKING

from softplc.util.lazy import lazy_exports

if TYPE_CHECKING:
    from softplc.adapters.hmi.server import HmiServer
    from softplc.adapters.hmi.settings import HmiSettings
    from softplc.adapters.hmi.shell import Page

# `softplc --help` must not import aiohttp: names load their module on first use (PEP 562).
_MODULES = {
    "softplc.adapters.hmi.server": ("HmiServer",),
    "softplc.adapters.hmi.settings": ("HmiSettings",),
    "softplc.adapters.hmi.shell": ("Page",),
}
__getattr__, __dir__ = lazy_exports(__name__, _MODULES)

__all__ = ["HmiServer", "HmiSettings", "Page"]
