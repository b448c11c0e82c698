"""Small camera frames of a run, kept in the Context: what a rollout's record shows of it.

:class:`CameraFrames` keeps one frame a second of the image the perception
reads (the object camera's ``object_color_image`` where the station has one,
else ``color_image``), downscaled to about 64 pixels across (every
``stride``-th pixel), in its abstract state: a rollout stopped early still
has its frames up to the stop, and a reset (``SetDefaultContext``) empties
them. Drake has no image logger (``LogVectorOutput`` logs vectors), hence
this system. It ticks with the camera (period 1 / fps, offset 0, the
segmenter's event times exactly, so the image is the one already rendered
and cached for the segmenter) and keeps every fps-th tick: t = 0, 1, 2 ... s.

:meth:`CameraFrames.now` gives the same reduction of the image at the
current state: the last frame of a run, at its end or its stop.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import EventStatus, LeafSystem
from pydrake.systems.sensors import ImageRgba8U

__all__ = ["CameraFrames", "add_camera_frames", "downscale"]


def downscale(image, stride: int) -> np.ndarray:
    """(H // stride, W // stride, 3) uint8 RGB: the pixels (stride k, stride l) of an ``ImageRgba8U``
    or an (H, W, >=3) array (nearest-pixel sampling; no filter, as the frames are for looking at)."""
    data = np.asarray(image.data if hasattr(image, "data") else image)
    return np.ascontiguousarray(data[::stride, ::stride, :3], dtype=np.uint8)


class CameraFrames(LeafSystem):
    """Input ``color_image`` (ImageRgba8U); state: (ticks so far, ((t [s], frame (h, w, 3) uint8), ...)),
    a frame kept at every ``every``-th tick of period ``period`` [s] from t = 0 (module docstring).
    No outputs: read with :meth:`frames`."""

    def __init__(self, period: float, every: int, stride: int):
        super().__init__()
        if not period > 0 or int(every) < 1 or int(stride) < 1:
            raise ValueError(f"CameraFrames: period {period!r} s, every {every!r}, stride {stride!r}: "
                             "expected > 0, >= 1 and >= 1")
        self._every, self._stride = int(every), int(stride)
        self._image = self.DeclareAbstractInputPort("color_image", AbstractValue.Make(ImageRgba8U()))
        self._state = self.DeclareAbstractState(AbstractValue.Make((0, ())))
        self.DeclarePeriodicUnrestrictedUpdateEvent(float(period), 0.0, self._tick)

    def _tick(self, context, state) -> EventStatus:
        ticks, frames = context.get_abstract_state(self._state).get_value()
        if ticks % self._every == 0:
            frame = downscale(self._image.Eval(context), self._stride)
            frame.setflags(write=False)     # shared by the tuples of later ticks, never changed
            frames = frames + ((context.get_time(), frame),)
        state.get_mutable_abstract_state(self._state).set_value((ticks + 1, frames))
        return EventStatus.Succeeded()

    def frames(self, context) -> tuple[np.ndarray, np.ndarray]:
        """(times (K,) [s], frames (K, h, w, 3) uint8) kept so far in this system's ``context``."""
        kept = context.get_abstract_state(self._state).get_value()[1]
        if not kept:
            return np.zeros(0), np.zeros((0, 0, 0, 3), dtype=np.uint8)
        return np.array([t for t, _ in kept]), np.stack([f for _, f in kept])

    def now(self, context) -> np.ndarray:
        """The image at ``context``'s state, downscaled as the kept ones (a run's last frame)."""
        return downscale(self._image.Eval(context), self._stride)


def _port_and_stride(station) -> tuple[object, int]:
    """The station's output the perception reads (module docstring) and the stride that brings its
    width to about 64 pixels."""
    camera = getattr(station, "object_camera", None)
    if camera is not None:
        return station.GetOutputPort(camera.image_port_names[0]), max(1, round(camera.window.width / 64))
    return station.GetOutputPort("color_image"), max(1, round(station.config.camera.width / 64))


def add_camera_frames(builder, station, seconds: float = 1.0) -> CameraFrames:
    """A :class:`CameraFrames` named ``camera_frames`` keeping a frame every ``seconds`` of the image
    the perception reads (``station.config.camera.fps``)."""
    fps = float(station.config.camera.fps)
    port, stride = _port_and_stride(station)
    frames = builder.AddNamedSystem("camera_frames", CameraFrames(1.0 / fps, max(1, round(seconds * fps)), stride))
    builder.Connect(port, frames.get_input_port())
    return frames
