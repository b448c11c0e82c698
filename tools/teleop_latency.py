#!/usr/bin/env python3
"""Teleoperation latency: key-down on drake-skill's page to 5 mm of hand motion (issue 51).

A script, not a test: it times a real session in real time (``realtime_rate``
1) with the page open in headless Chromium (tests/browser_support.py, the
page tests' browser), with the camera on (rendered and segmented at 10 Hz
while recording, as ``demos record --interactive`` does) and off. Each trial
presses W (or S, alternating, so the hand goes back and forth) twice, a 10 mm
target step, from a browser thread; the session's thread reads the measured
hand pose every 10 ms of simulation and stamps the wall time at which the
hand is 5 mm from where it was at the key. Prints JSON:

    {"machine": "...", "camera_on": {"median_s": .., "p95_s": .., "n": ..}, "camera_off": {...}}

    .venv/bin/python tools/teleop_latency.py [--trials 20] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))


class Trials:
    """The browser's thread presses keys; the session's thread (``user(t)``) watches the hand."""

    def __init__(self, session, driver, page, trials: int):
        self.session, self.driver, self.page, self.trials = session, driver, page, trials
        self.port = session.station.GetOutputPort("ee_pose")
        self.station_context = session.station.GetMyContextFromRoot(session.context)
        self.lock = threading.Lock()
        self.start = None            # (wall time of key-down, hand position then)
        self.latencies: list[float] = []
        self.recording = threading.Event()
        self.reached = threading.Event()
        self.finished = False

    def hand(self) -> np.ndarray:
        return self.port.Eval(self.station_context).translation().copy()

    def user(self, t: float) -> None:
        """Called before every 10 ms simulation step."""
        if self.session.mode() == 1:
            self.recording.set()
        with self.lock:
            if self.start is not None and np.linalg.norm(self.hand() - self.start[1]) >= 0.005:
                self.latencies.append(time.time() - self.start[0])
                self.start = None
                self.reached.set()

    def press(self) -> None:
        """The browser thread: Record, the trials, Stop."""
        from selenium.webdriver.common.action_chains import ActionChains

        keys = lambda text: ActionChains(self.driver).send_keys(text).perform()   # noqa: E731
        self.driver.get(self.page.url)
        time.sleep(2.0)                      # the page and the Meshcat view load
        keys("r")
        self.recording.wait(30)
        time.sleep(1.0)
        for i in range(self.trials):
            self.reached.clear()
            with self.lock:
                self.start = (time.time(), self.hand())
            keys("ww" if i % 2 == 0 else "ss")
            if not self.reached.wait(10):
                print(f"trial {i}: the hand did not move 5 mm within 10 s", file=sys.stderr)
            time.sleep(0.6)                  # the hand settles at the new target
        keys("t")
        self.finished = True


def measure(camera: bool, trials: int) -> dict:
    from pydrake.geometry import Meshcat

    from browser_support import headless_chrome
    from drake_skill.demos.teleop import TeleopConfig, TeleopSession, open_page
    from drake_skill.skills import load_skill

    station = load_skill("open").station_config()
    station.enable_camera = camera
    meshcat = Meshcat()
    config = TeleopConfig(realtime_rate=1.0, record_perception=camera, max_duration=trials * 3.0 + 20)
    driver = headless_chrome()
    with open_page(meshcat, "latency") as page:
        session = TeleopSession("open", meshcat, config, station_config=station, page=page)
        run = Trials(session, driver, page, trials)
        thread = threading.Thread(target=run.press, daemon=True)
        thread.start()
        try:
            session.record(0, user=run.user, status=lambda line: print(line, file=sys.stderr))
        finally:
            driver.quit()
    lat = np.array(run.latencies)
    return {"median_s": round(float(np.median(lat)), 3), "p95_s": round(float(np.percentile(lat, 95)), 3),
            "n": int(lat.size)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--out", type=Path, help="also write the JSON here")
    args = parser.parse_args(argv)
    result = {"machine": f"{platform.node()}: {os.cpu_count()} CPUs, {platform.processor() or platform.machine()}",
              "camera_on": measure(True, args.trials), "camera_off": measure(False, args.trials)}
    text = json.dumps(result, indent=1)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
