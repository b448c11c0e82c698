"""What every box shares, with no Drake import: the size of an object cloud, the
camera's look-at pose, Meshcat's view of the workspace, the counter of
differential-IK warnings, SIGTERM as an interrupt."""

from __future__ import annotations

import contextlib
import logging
import signal

import numpy as np

#: Points per segmented object cloud, the PCAE's input size N (docs/method.md section 3).
N_POINTS = 2048


def look_at(eye, target, roll_rad: float = 0.0) -> np.ndarray:
    """4x4 pose X_WC [m] of a camera at ``eye`` looking at ``target`` (world frame, z up).

    Drake's camera convention: +z along the optical axis, +x right, +y down;
    ``roll_rad`` turns the camera about its optical axis. Raises ValueError
    when eye and target coincide or the view is vertical (the roll is then
    undefined).
    """
    eye = np.asarray(eye, dtype=np.float64)
    fwd = np.asarray(target, dtype=np.float64) - eye
    n = np.linalg.norm(fwd)
    if n < 1e-9:
        raise ValueError(f"look_at: eye {eye} and target {target} coincide")
    fwd /= n
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    if np.linalg.norm(right) < 1e-6:
        raise ValueError(f"look_at: view direction {fwd} is vertical; the camera roll is undefined")
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    c, s = np.cos(roll_rad), np.sin(roll_rad)
    roll = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    X = np.eye(4)
    X[:3, :3] = np.stack([right, down, fwd], axis=1) @ roll
    X[:3, 3] = eye
    return X


class IkWarningCounter(logging.Filter):
    """Counts differential IK's "no solution"/"stuck" warnings on the ``drake`` logger.

    They come whenever a commanded hand pose is out of reach (a DMP exploring
    far from the demonstrations does that). ``suppress=True`` also keeps them
    from printing (the command line, unless ``--verbose``); otherwise they pass.
    """

    def __init__(self, suppress: bool = False):
        super().__init__()
        self.suppress = suppress
        self.count = 0

    def filter(self, record):
        if "Differential IK" in record.getMessage():
            self.count += 1
            return not self.suppress
        return True


@contextlib.contextmanager
def terminate_as_interrupt():
    """Within: SIGTERM raises KeyboardInterrupt, as Ctrl-C does, so that the same handler keeps
    what was finished (``kill PID`` of a recording). The previous handler is restored after;
    only the main thread can install one (elsewhere this does nothing)."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum, frame):
        raise KeyboardInterrupt(f"signal {signum}")

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def frame_meshcat_camera(meshcat, object_xyz) -> None:
    """Points Meshcat's camera at the robot and the object (robot base at the world origin):
    from the front left, above, at the point halfway between them, 0.25 m up."""
    target = 0.5 * np.asarray(object_xyz, dtype=float) + np.array([0.0, 0.0, 0.25])   # between base and object
    meshcat.SetCameraPose(target + np.array([0.9, -1.3, 0.55]), target)


def recorded_html(meshcat, action, *, fps: float = 32.0, live: bool = False):
    """Runs ``action()`` while ``meshcat`` records (``live``: also drawn as it runs); returns
    ``(action's result, the recording as one standalone HTML page)`` and deletes the recording."""
    meshcat.StartRecording(frames_per_second=fps, set_visualizations_while_recording=live)
    try:
        result = action()
    finally:
        meshcat.StopRecording()
    meshcat.PublishRecording()
    html = meshcat.StaticHtml()
    meshcat.DeleteRecording()
    return result, html
