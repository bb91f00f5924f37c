"""The viewer in a real browser: Debian's headless Chromium driven by Playwright (the
``dev`` extra; never ``playwright install``: the browser is ``/usr/bin/chromium``, which
``make test`` installs). Used by tests/test_view_browser.py and to take the screenshots
in docs/ (docs/viewer.md)::

    .venv/bin/python -m planner_service.view.browser plan.html shot.png --time 3.0

WebGL without a GPU runs on SwiftShader (``--use-angle=swiftshader``).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path
from typing import Any

__all__ = ["CHROMIUM", "CHROMIUM_FLAGS", "launch", "main", "open_view"]

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_FLAGS = (
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
)
#: How long a page may take to draw its first frame [ms] (SwiftShader on a loaded machine).
READY_TIMEOUT_MS = 120_000


def launch(playwright: Any, profile: Path) -> Any:
    """Chromium headless with a fresh profile folder ``profile``: a persistent context
    (the only way to give Chromium its own --user-data-dir through Playwright)."""
    return playwright.chromium.launch_persistent_context(
        str(profile), executable_path=CHROMIUM, headless=True, args=list(CHROMIUM_FLAGS),
        viewport={"width": 1000, "height": 700}, device_scale_factor=1)


def open_view(page: Any, url: str) -> None:
    """Load a viewer page and wait until it has drawn (or failed: ``dexroll.error``)."""
    page.goto(url)
    page.wait_for_function("window.dexroll && (window.dexroll.ready || window.dexroll.error)",
                           timeout=READY_TIMEOUT_MS)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="screenshot a viewer page at a time")
    parser.add_argument("page", help="the page (a file or a URL)")
    parser.add_argument("png", help="the screenshot to write")
    parser.add_argument("--time", type=float, default=0.0, help="plan time [s]")
    parser.add_argument("--width", type=int, default=1000)
    parser.add_argument("--height", type=int, default=700)
    args = parser.parse_args(argv)
    from playwright.sync_api import sync_playwright

    url = args.page if "://" in args.page else Path(args.page).resolve().as_uri()
    with sync_playwright() as p, tempfile.TemporaryDirectory() as profile:
        context = launch(p, Path(profile))
        page = context.pages[0] if context.pages else context.new_page()
        page.set_viewport_size({"width": args.width, "height": args.height})
        open_view(page, url)
        error = page.evaluate("window.dexroll.error")
        if error:
            print(f"the page failed: {error}", file=sys.stderr)
            return 1
        page.evaluate("t => window.dexroll.setTime(t)", args.time)
        page.screenshot(path=args.png)
        context.close()
    print(args.png)
    return 0


if __name__ == "__main__":
    sys.exit(main())
