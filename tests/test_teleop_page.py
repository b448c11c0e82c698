"""drake-skill's teleoperation page (issue 51 item 1): its server without a browser, and the
whole page in a real headless Chromium: keys drive the hand, a recording is saved, the page
shows its state, and a key typed into a focused text box does not move the hand."""

import json
import time
import urllib.request

import numpy as np
import pytest
from pydrake.geometry import Meshcat

from browser_support import headless_chrome, missing
from drake_skill.demos.teleop import (
    RECORD_KEY,
    SLIDERS,
    STOP_KEY,
    TeleopConfig,
    open_page,
    record_interactive_into,
)
from drake_skill.demos.teleop_page import PageClosed, TeleopPage
from drake_skill.skills import load_skill


pytestmark = pytest.mark.usefixtures("quiet_differential_ik")


def _post(page, route, body):
    request = urllib.request.Request(page.url + route, data=json.dumps(body).encode(), method="POST")
    try:
        return urllib.request.urlopen(request, timeout=5).status
    except urllib.error.HTTPError as error:
        return error.code


def _status(page):
    return json.loads(urllib.request.urlopen(page.url + "status", timeout=5).read())


def test_the_page_counts_keys_owns_the_status_and_notices_a_close():
    keys = [(dec, inc) for _, dec, inc in SLIDERS]
    with TeleopPage("http://localhost:7000", keys, RECORD_KEY, STOP_KEY, heartbeat_timeout=0.3) as page:
        assert page.url.startswith("http://127.0.0.1:")
        html = urllib.request.urlopen(page.url, timeout=5).read().decode()
        assert '<iframe id="view" src="http://localhost:7000">' in html and '"KeyW"' in html
        for code in ("KeyW", "KeyW", "KeyS", "KeyA", "KeyX", "KeyR", "KeyR", "KeyT"):
            assert _post(page, "key", {"code": code}) == 200
        assert _post(page, "key", {"code": "KeyP"}) == 400          # not a key of the page
        np.testing.assert_array_equal(page.take_key_steps(), [1, 1, 0, 0, 0, 0, 1])
        np.testing.assert_array_equal(page.take_key_steps(), np.zeros(7))   # taken once
        assert page.clicks() == (2, 1)
        page.reset_clicks()
        assert page.clicks() == (0, 0)
        page.publish(mode="recording", recording_s=1.25)
        assert _status(page) == {"mode": "recording", "recording_s": 1.25}
        _post(page, "note", {"text": "lid stuck at first"})
        assert page.note == "lid stuck at first"
        assert not page.closed                                        # polled just now
        time.sleep(0.4)
        assert page.closed                                            # no poll for heartbeat_timeout
        with pytest.raises(PageClosed):
            page.check_open()
    with TeleopPage("http://localhost:7000", keys, RECORD_KEY, STOP_KEY) as page:
        assert not page.closed                                        # never connected: not closed
        _post(page, "closed", {})                                     # the page's pagehide beacon
        assert page.closed


class _BrowserUser:
    """The person at the keyboard, as a ``user(t)`` of TeleopSession.record: each step runs
    in simulation time, and each waits in wall time until the page's server got it."""

    def __init__(self, driver, page, session_mode):
        from selenium.webdriver.common.action_chains import ActionChains
        from selenium.webdriver.common.by import By
        from selenium.webdriver.support.ui import WebDriverWait

        self.driver, self.page, self.mode = driver, page, session_mode
        self.find = lambda id_: driver.find_element(By.ID, id_)
        self.wait = lambda until: WebDriverWait(driver, 30, poll_frequency=0.05).until(lambda _: until())
        self.keys = lambda text: ActionChains(driver).send_keys(text).perform()
        self.step, self.t_recording, self.seen = 0, None, {}

    def __call__(self, t):
        if self.step == 0:                      # the page opens on the idle session
            self.driver.get(self.page.url)
            self.wait(lambda: self.find("mode").text == "idle")
            self.seen["idle"] = (self.find("demo").text, self.find("limits").text)
            note = self.find("note")            # typed into the focused box: not a key of the hand
            note.click()
            note.send_keys("w")
            self.wait(lambda: self.page.note == "w")
            self.wait(lambda: self.find("keys").text != "keys: live")
            self.seen["keys_while_typing"] = self.find("keys").text
            time.sleep(0.3)
            self.seen["typed_keys"] = len(self.page.key_times())
            self.find("demo").click()           # focus back on the panel
            self.keys("r")
            self.wait(lambda: self.page.clicks()[0] == 1)
            self.step = 1
        elif self.step == 1 and self.mode() == 1:
            self.t_recording = t
            self.keys("wwww")                   # +4 x 5 mm along x
            self.wait(lambda: len(self.page.key_times()) == 5)
            self.step = 2
        elif self.step == 2 and t >= self.t_recording + 1.0:
            self.wait(lambda: self.find("mode").text.startswith("recording"))
            self.seen["recording"] = self.find("mode").text
            self.keys("t")
            self.wait(lambda: self.page.clicks()[1] == 1)
            self.step = 3


@pytest.mark.skipif(missing() is not None, reason=str(missing()))
def test_keys_in_a_real_browser_drive_the_hand_and_the_page_shows_the_state(tmp_path):
    from drake_skill.demos.format import load_demonstrations

    station = load_skill("open").station_config()
    station.enable_camera = False
    station.success.above = -1.0          # any lid angle is a success: the judge is not under test
    meshcat = Meshcat()
    config = TeleopConfig(realtime_rate=0.0, record_perception=False)
    driver = headless_chrome()
    with open_page(meshcat, "drake-skill teleoperation: open") as page:
        try:
            lines = []
            user = _BrowserUser(driver, page, lambda: _session_mode(page))
            paths, (demo,) = record_interactive_into(tmp_path / "by_hand", "open", 1, meshcat=meshcat,
                                                     config=config, station_config=station, user=user,
                                                     page=page, status=lines.append)
            user.wait(lambda: user.find("demo").text.endswith("(kept 1)"))   # the page polls every 0.2 s
            shown = {id_: user.find(id_).text for id_ in ("mode", "last", "demo")}
        finally:
            driver.quit()
    assert user.seen["idle"][0] == "demonstration 1 of 1 (kept 0)"
    assert "press Record within 600.0 s" in user.seen["idle"][1] and "after 120.0 s" in user.seen["idle"][1]
    assert user.seen["keys_while_typing"] == "keys: off while a text box has focus"
    assert user.seen["typed_keys"] == 0                    # the W typed into the note reached no key
    assert user.seen["recording"].startswith("recording ") and user.seen["recording"].endswith(" s")
    assert shown["mode"] == "done" and shown["demo"] == "demonstration 1 of 1 (kept 1)"
    assert shown["last"].startswith("last: success (lid_hinge ") and "the hand left" in shown["last"]
    # The four W presses moved the hand 20 mm along the world x, nothing else.
    (kept,) = load_demonstrations(tmp_path / "by_hand")
    assert paths[0].name == "demo_000.npz" and kept.metadata["note"] == "w"
    moved_O = demo.X_OE_100hz[-1, :3] - demo.X_OE_100hz[0, :3]
    assert np.linalg.norm(moved_O) == pytest.approx(0.020, abs=0.003)
    assert any(line.startswith(f"open {page.url}") for line in lines)


def _session_mode(page):
    return {"idle": 0, "recording": 1, "done": 2}.get(page.status().get("mode"), -1)
