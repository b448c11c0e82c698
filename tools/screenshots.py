#!/usr/bin/env python3
"""The README's screenshots, taken in the page tests' headless Chromium (tests/browser_support.py).

    .venv/bin/python tools/screenshots.py [--run results/learn/open] [--out docs/screenshots]

* ``teleop_page.png``: drake-skill's teleoperation page (Open, camera off)
  during a recording, after a first demonstration whose verdict it shows;
  the keys are pressed in the browser, as a person would.
* ``run_report.png``: RUN/report.html, the learn run's report (``make demo``
  writes results/learn/open);
* ``fit_report.png``: the fit report of Open's demonstrations recorded
  afresh (``drake-skill demos record`` and ``fit``, in a temporary folder).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))


class _Done(Exception):
    """Raised from the user hook once the screenshot is taken."""


def teleop_page(out: Path) -> None:
    from pydrake.geometry import Meshcat
    from selenium.webdriver.common.action_chains import ActionChains

    from browser_support import headless_chrome
    from drake_skill.demos.teleop import TeleopConfig, open_page, record_interactive
    from drake_skill.skills import load_skill

    station = load_skill("open").station_config()
    station.enable_camera = False
    meshcat = Meshcat()
    driver = headless_chrome(1400, 800)
    keys = lambda text: ActionChains(driver).send_keys(text).perform()   # noqa: E731
    phase = {"demo": 0, "t0": None}

    def user(t):
        status = page.status().get("mode")
        if phase["t0"] is None:
            driver.get(page.url)
            time.sleep(4.0)                          # the Meshcat view loads and draws
            phase["t0"] = t
        if status == "idle" and t > phase["t0"] + 0.2:
            keys("r")
            time.sleep(0.3)
        elif status == "recording" and phase["demo"] == 0 and t > phase["t0"] + 1.0:
            keys("wwwwqqqq")
            time.sleep(0.3)
            keys("t")
            phase["demo"] = 1
            time.sleep(0.3)
        elif status == "recording" and phase["demo"] == 1 and (page.status().get("recording_s") or 0) > 1.5:
            time.sleep(1.0)
            driver.save_screenshot(str(out / "teleop_page.png"))
            raise _Done

    with open_page(meshcat, "drake-skill teleoperation: open") as page:
        try:
            record_interactive("open", 1, config=TeleopConfig(realtime_rate=0.0, record_perception=False),
                               meshcat=meshcat, station_config=station, user=user, page=page, status=print)
        except _Done:
            pass
        finally:
            driver.quit()


def report(html: Path, png: Path) -> None:
    from browser_support import headless_chrome

    if not html.exists():
        raise SystemExit(f"screenshots: {html} does not exist; run `make demo` first (it writes results/learn/open)")
    driver = headless_chrome(1280, 1500)
    try:
        driver.get(html.resolve().as_uri())
        time.sleep(1.0)
        driver.save_screenshot(str(png))
    finally:
        driver.quit()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--run", type=Path, default=ROOT / "results/learn/open")
    parser.add_argument("--out", type=Path, default=ROOT / "docs/screenshots")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    report(args.run / "report.html", args.out / "run_report.png")
    with tempfile.TemporaryDirectory() as tmp:
        from drake_skill.cli.main import main as drake_skill

        for command in (["demos", "record", "--skill", "open", "--out", f"{tmp}/demos", "--quiet"],
                        ["fit", "--demos", f"{tmp}/demos", "--out", f"{tmp}/skill", "--skill", "open"]):
            if drake_skill(command):
                raise SystemExit(f"screenshots: drake-skill {' '.join(command)} failed")
        report(Path(tmp) / "skill" / "fit_report.html", args.out / "fit_report.png")
    teleop_page(args.out)
    for name in ("teleop_page", "run_report", "fit_report"):
        print(f"wrote {args.out / name}.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
