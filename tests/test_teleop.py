"""Interactive teleoperation: input logic with fake inputs, and a recorded demonstration driven
through a real Meshcat (no browser: slider values set and button clicks / gamepad injected as the
browser's websocket messages, as Drake's own Meshcat tests do)."""

import struct

import numpy as np
import pytest
from pydrake.geometry import Meshcat
from pydrake.math import RigidTransform, RollPitchYaw

from drake_skill.demos.teleop import (
    DONE,
    IDLE,
    RECORD_BUTTON,
    RECORDING,
    SLIDERS,
    STOP_BUTTON,
    TeleopConfig,
    TeleopInputs,
    TeleopSession,
    TeleopState,
    slider_limits,
    target_pose,
    teleop_step,
)


pytestmark = pytest.mark.usefixtures("quiet_differential_ik")


SLIDER = {name.split()[0]: name for name, _, _ in SLIDERS}
HOME = RigidTransform(RollPitchYaw(np.pi, 0.0, 0.0), [0.4, 0.0, 0.5])


def _pack(obj) -> bytes:
    """Minimal msgpack encoder for the browser messages Meshcat accepts."""
    if isinstance(obj, dict):
        return bytes([0x80 | len(obj)]) + b"".join(_pack(k) + _pack(v) for k, v in obj.items())
    if isinstance(obj, str):
        data = obj.encode()
        return bytes([0xA0 | len(data)]) + data
    if isinstance(obj, (list, tuple)):
        return bytes([0x90 | len(obj)]) + b"".join(_pack(x) for x in obj)
    if isinstance(obj, bool):
        return b"\xc3" if obj else b"\xc2"
    if isinstance(obj, int) and 0 <= obj < 128:
        return bytes([obj])
    return b"\xcb" + struct.pack(">d", float(obj))


def click(meshcat, name):
    meshcat._InjectWebsocketMessage(_pack({"type": "button", "name": name}))


def _inputs(sliders=None, **kw):
    return TeleopInputs(np.r_[HOME.translation(), 0, 0, 0, 0.0] if sliders is None else sliders, **kw)


def test_record_and_stop_clicks_drive_the_mode():
    config = TeleopConfig()
    lo, hi, _ = slider_limits(HOME, config)
    state = TeleopState(np.r_[HOME.translation(), 0, 0, 0, 0.0])
    state, _ = teleop_step(state, _inputs(stop_clicks=1), 0.01, config, lo, hi)
    assert state.mode == IDLE and state.seen_stop == 1            # stop before record: ignored
    state, _ = teleop_step(state, _inputs(record_clicks=1, stop_clicks=1), 0.01, config, lo, hi)
    assert state.mode == RECORDING
    state, _ = teleop_step(state, _inputs(record_clicks=2, stop_clicks=1), 0.01, config, lo, hi)
    assert state.mode == RECORDING                                # record again: still recording
    state, _ = teleop_step(state, _inputs(record_clicks=2, stop_clicks=2), 0.01, config, lo, hi)
    assert state.mode == DONE
    np.testing.assert_array_equal(TeleopState.from_vector(state.to_vector()).to_vector(), state.to_vector())


def test_sliders_are_clipped_and_gamepad_adds_velocity():
    config = TeleopConfig()
    lo, hi, _ = slider_limits(HOME, config)
    state = TeleopState(np.r_[HOME.translation(), 0, 0, 0, 0.0])
    far = np.r_[HOME.translation() + [2.0, 0.0, 0.0], 0, 0, 500.0, 0.5]
    state, moved = teleop_step(state, _inputs(far), 0.01, config, lo, hi)
    assert not moved
    np.testing.assert_allclose(state.target, np.r_[HOME.translation() + [0.5, 0, 0], 0, 0, 180.0, 0.08])
    # Full left stick forward (-1 on axis 1) for 0.5 s at 0.15 m/s: +7.5 cm in x; small axes are dead.
    state = TeleopState(np.r_[HOME.translation(), 0, 0, 0, 0.0])
    axes = np.array([0.05, -1.0, 0.0, 0.0])
    buttons = np.zeros(16)
    buttons[7] = 1.0                                             # right trigger: open
    for _ in range(50):
        state, moved = teleop_step(state, _inputs(state.target, gamepad_axes=axes, gamepad_buttons=buttons),
                                   0.01, config, lo, hi)
        assert moved
    np.testing.assert_allclose(state.target[:3], HOME.translation() + [0.075, 0.0, 0.0], atol=1e-12)
    assert state.target[6] == pytest.approx(0.025)
    # Gamepad A starts recording on the press, not while held; B stops.
    buttons = np.zeros(16)
    buttons[0] = 1.0
    state, _ = teleop_step(state, _inputs(state.target, gamepad_axes=np.zeros(4), gamepad_buttons=buttons),
                           0.01, config, lo, hi)
    assert state.mode == RECORDING
    buttons[[0, 1]] = [0.0, 1.0]
    state, _ = teleop_step(state, _inputs(state.target, gamepad_axes=np.zeros(4), gamepad_buttons=buttons),
                           0.01, config, lo, hi)
    assert state.mode == DONE


def test_target_pose_applies_world_rpy_on_top_of_home():
    X = target_pose(np.r_[0.5, 0.1, 0.3, 0.0, 0.0, 90.0, 0.0], HOME.rotation())
    np.testing.assert_allclose(X.translation(), [0.5, 0.1, 0.3])
    # Home points down with x_E along world x; a 90 degree world yaw turns x_E to world y.
    R = X.rotation().matrix()
    np.testing.assert_allclose(R[:, 0], [0.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(R[:, 2], [0.0, 0.0, -1.0], atol=1e-12)


def test_meshcat_driven_demonstration_is_recorded():
    """A scripted 'user' on a real Meshcat: record, push the sliders, stop."""
    meshcat = Meshcat()
    config = TeleopConfig(realtime_rate=0.0, record_perception=False)
    session = TeleopSession("open", meshcat, config)
    # The controls are on the page, keyboard keys attached.
    assert set(meshcat.GetSliderNames()) == {name for name, _, _ in SLIDERS}
    assert {RECORD_BUTTON, STOP_BUTTON} <= set(meshcat.GetButtonNames())
    start = {}

    def user(t):
        if not start and t >= 0.3:
            start["x"] = meshcat.GetSliderValue(SLIDER["x"])
            start["z"] = meshcat.GetSliderValue(SLIDER["z"])
            click(meshcat, RECORD_BUTTON)
        elif start and t <= 1.4:
            s = min(max((t - 0.45) / 0.8, 0.0), 1.0)       # ramp 0.45 .. 1.25 s
            meshcat.SetSliderValue(SLIDER["x"], start["x"] + 0.10 * s)
            meshcat.SetSliderValue(SLIDER["z"], start["z"] - 0.08 * s)
            meshcat.SetSliderValue(SLIDER["gripper"], 0.04 * s)
        if 1.95 <= t < 1.96:
            click(meshcat, STOP_BUTTON)

    demo = session.record(seed=0, user=user, status=lambda *_: None)
    assert demo.metadata["source"] == "interactive"
    assert demo.metadata["recording_started_at_s"] == pytest.approx(0.4)   # next camera frame after 0.31 s
    # Recorded from the frame after Record until the frame after Stop: 0.4 .. 2.0 s.
    assert demo.duration == pytest.approx(1.6)
    assert demo.X_OE_100hz.shape == (161, 7) and demo.X_OE.shape == (17, 7)
    assert not demo.has_perception
    # The hand moved as commanded: +10 cm x, -8 cm z in the world; X_OE = X_WO^-1 X_WE.
    X_WO = session.X_WO
    R_OW = X_WO.rotation().inverse().matrix()
    moved_W = R_OW.T @ (demo.X_OE_100hz[-1, :3] - demo.X_OE_100hz[0, :3])
    np.testing.assert_allclose(moved_W, [0.10, 0.0, -0.08], atol=0.006)
    np.testing.assert_allclose(demo.gripper_100hz[[0, -1]], [0.0, 0.04], atol=1e-9)
    assert demo.final_object_state == pytest.approx(0.0, abs=1e-3) and not demo.success
    assert session.mode() == DONE
    # Reset puts the controls back at home with no pending clicks.
    session.reset(0)
    assert meshcat.GetButtonClicks(RECORD_BUTTON) == 0 and session.mode() == IDLE
    assert meshcat.GetSliderValue(SLIDER["x"]) == pytest.approx(start["x"], abs=0.005)


def test_idle_session_runs_20_s_without_a_solver_failure():
    """Left idle (no browser input, gripper commanded closed), the session waits the
    whole max_wait of 20 s (7x the time of the failure): the SAP failure at rest (issue 10,
    t = 2.668 s) is gone. (It waited 60 s until the suite's time had to be cut.)"""
    meshcat = Meshcat()
    config = TeleopConfig(realtime_rate=0.0, record_perception=False, max_wait=20.0)
    session = TeleopSession("open", meshcat, config)
    assert session.station.config.gripper_home == 0.0
    with pytest.raises(TimeoutError, match="not pressed within 20.0 s"):
        session.record(seed=0, status=lambda *_: None)
    assert session.context.get_time() > 20.0
    assert session.mode() == IDLE


@pytest.mark.parametrize("stop", ["sigterm", "page closed"])
def test_an_interrupted_teleoperation_keeps_its_finished_demonstration(tmp_path, capsys, stop):
    """After 1 of 2 demonstrations, SIGTERM (as Ctrl-C) or closing the page keeps that one: with
    --force it replaces the old set, and the folder lists (issue 51 item 1)."""
    import signal
    import urllib.request

    from drake_skill.cli.main import main
    from drake_skill.demos.format import load_demonstrations
    from drake_skill.demos.teleop import RecordingInterrupted, open_page, record_interactive_into
    from drake_skill.skills import load_skill

    station = load_skill("open").station_config()
    station.enable_camera = False
    station.success.above = -1.0          # any lid angle is a success: the judge is not under test
    old = tmp_path / "open"
    old.mkdir()
    (old / "demo_000.npz").write_bytes(b"an old set")
    (old / "demo_001.npz").write_bytes(b"an old set")
    meshcat = Meshcat()
    page = open_page(meshcat, "test")
    demos_done, lines = [], []

    def user(t):
        if 0.3 <= t < 0.31:
            click(meshcat, RECORD_BUTTON)
        if 1.45 <= t < 1.46:
            if demos_done and stop == "sigterm":  # the second demonstration: the user stops the program
                signal.raise_signal(signal.SIGTERM)
            elif demos_done:                      # ... or closes the page (its pagehide beacon)
                urllib.request.urlopen(urllib.request.Request(page.url + "closed", data=b"{}"), timeout=5)
            click(meshcat, STOP_BUTTON)

    config = TeleopConfig(realtime_rate=0.0, record_perception=False)
    handler = signal.getsignal(signal.SIGTERM)        # pytest-xdist's worker has one of its own
    why = "interrupted" if stop == "sigterm" else "the teleoperation page was closed"
    with page, pytest.raises(RecordingInterrupted, match=f"^{why}; kept the 1 finished demonstration.*replace"):
        record_interactive_into(old, "open", 2, force=True, meshcat=meshcat, config=config, user=user, page=page,
                                station_config=station, status=lambda line: (lines.append(line), demos_done.append(line)
                                                                             if "kept" in line else None))
    (kept,) = load_demonstrations(old)
    assert kept.metadata["source"] == "interactive" and kept.duration == pytest.approx(1.1)
    # The time limits were announced (issue 51: they were not).
    assert "Record (R) (within 600 s)" in " ".join(lines) and "stops by itself after 120 s" in " ".join(lines)
    assert not old.with_name(".open.recording").exists()
    assert signal.getsignal(signal.SIGTERM) is handler      # the handler is restored
    assert main(["demos", "list", str(old)]) == 0
    assert "demo_000.npz" in capsys.readouterr().out


def test_a_staging_folder_left_by_a_killed_session_is_never_cleared(tmp_path):
    from drake_skill.demos.format import DemoSetWriter

    (tmp_path / "set").mkdir()
    (tmp_path / "set" / "demo_000.npz").write_bytes(b"old")
    (tmp_path / ".set.recording").mkdir()
    with pytest.raises(FileExistsError, match="interrupted session; move them"):
        DemoSetWriter(tmp_path / "set", force=True)
    with pytest.raises(FileExistsError, match="pass --force"):
        DemoSetWriter(tmp_path / "set")
    writer = DemoSetWriter(tmp_path / "new")
    assert writer.target == tmp_path / "new"
    assert writer.interrupted() == f"kept the 0 finished demonstration(s) in {tmp_path / 'new'}"
