"""Opening the HMI in the user's browser (`softplc run --hmi-open`, what ./run.sh does), when there is a screen."""

from __future__ import annotations

import logging
import os
import sys
import threading
import webbrowser

log = logging.getLogger(__name__)


def has_display() -> bool:
    """Whether a browser window could be shown: a desktop session (or macOS / Windows)."""
    if sys.platform == "darwin" or os.name == "nt":
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def open_later(url: str) -> bool:
    """Open `url` in the default browser from a thread (launching one may take a while); False without a display."""
    if not has_display():
        return False

    def run() -> None:
        try:
            webbrowser.open(url, new=2)
        except Exception as error:  # no browser installed: the URL is printed anyway
            log.info("HMI: could not open a browser: %s", error)

    threading.Thread(target=run, name="softplc-hmi-browser", daemon=True).start()
    return True
