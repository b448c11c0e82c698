"""Headless Chromium for the page tests and the README's screenshots (tools/screenshots.py).

Debian's ``chromium`` and ``chromium-driver`` are installed by ``make test``'s
test-only step (``tools/ensure_system_deps.sh --test``), selenium comes from
the test extra. WebGL (the Meshcat view) renders on the CPU through SwiftShader.
"""

from __future__ import annotations

import shutil

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"


def missing() -> str | None:
    """Why no browser can start here, or None."""
    for path in (CHROMIUM, CHROMEDRIVER):
        if shutil.which(path) is None:
            return f"{path} is not installed (make test installs Debian's chromium and chromium-driver)"
    return None


def headless_chrome(width: int = 1280, height: int = 800):
    """A selenium ``webdriver.Chrome`` on headless Chromium at ``width`` x ``height`` pixels."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--use-angle=swiftshader",
                "--enable-unsafe-swiftshader", f"--window-size={width},{height}",
                "--disable-background-timer-throttling", "--disable-renderer-backgrounding"):
        options.add_argument(arg)
    return webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
