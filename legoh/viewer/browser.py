"""A headless Chromium looking at the web viewer: the browser test and the README's
screenshot use it (the ``viewer`` and ``dev`` extras install Playwright; the browser is
Debian's ``chromium``, which ``.ci/run`` installs, never a download of Playwright's own).
"""

from __future__ import annotations

import os
import re
import shutil
import time
from collections.abc import Iterator
from contextlib import contextmanager
from io import BytesIO

import numpy as np

# Headless as root on a machine with no GPU and a closed network: no sandbox (root), no
# GPU process, WebGL on SwiftShader, and none of the background calls home that the
# network would refuse at every start.
CHROMIUM_ARGS = ("--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader",
                 "--disable-quic", "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync")
CANDIDATES = ("chromium", "chromium-browser", "google-chrome")
VIEWPORT = {"width": 1280, "height": 800}  # px: software WebGL's cost grows with it


def find_chromium() -> str | None:
    """The Chromium to drive: ``$CHROMIUM`` or the first of ``CANDIDATES`` on the PATH."""
    if os.environ.get("CHROMIUM"):
        return os.environ["CHROMIUM"]
    return next((p for p in map(shutil.which, CANDIDATES) if p), None)


@contextmanager
def open_page(url: str, chromium: str | None = None, timeout_s: float = 120.0,
              viewport: dict | None = None) -> Iterator:
    """A Playwright page of ``url`` in headless Chromium (``viewport``: px, default
    ``VIEWPORT``), once the viewer has sent its scene (its caption, the last thing a
    rollout's load writes, is on the page)."""
    from playwright.sync_api import sync_playwright

    chromium = chromium or find_chromium()
    if chromium is None:
        raise FileNotFoundError(f"no Chromium found (tried $CHROMIUM and {CANDIDATES}); "
                                "Debian: apt-get install chromium")
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, args=list(CHROMIUM_ARGS),
                                    headless=True)
        try:
            page = browser.new_page(viewport=viewport or VIEWPORT)
            page.set_default_timeout(timeout_s * 1000)
            page.goto(url)
            page.get_by_text(re.compile(r"robot \d+ ·")).first.wait_for()
            yield page
        finally:
            browser.close()


def canvas_pixels(page) -> np.ndarray:
    """(H, W, 3) uint8 screenshot of the page's 3-D canvas."""
    from PIL import Image

    png = page.locator("canvas").first.screenshot()
    return np.asarray(Image.open(BytesIO(png)).convert("RGB"))


def settled_canvas(page, quiet_ms: int = 1000, timeout_ms: int = 90000,
                   tolerance: float = 5e-4) -> np.ndarray:
    """The canvas once two shots ``quiet_ms`` apart differ in fewer than ``tolerance`` of
    its pixels (software WebGL on a busy machine draws the first frames slowly, and
    antialiased edges flicker by a few levels)."""
    last, start = canvas_pixels(page), time.monotonic()
    while (time.monotonic() - start) * 1000 < timeout_ms:
        page.wait_for_timeout(quiet_ms)
        now = canvas_pixels(page)
        if changed(now, last).mean() < tolerance:
            return now
        last = now
    return last


def changed(a: np.ndarray, b: np.ndarray, threshold: int = 30) -> np.ndarray:
    """(H, W) bool: pixels where two screenshots differ by more than ``threshold`` (0-255)
    in some channel."""
    return np.abs(a.astype(int) - b.astype(int)).max(axis=-1) > threshold
