"""The perception boxes of the diagram (docs/architecture.md): Drake wrappers over
the Drake-free math of :mod:`drake_skill.perception.segmentation`,
:mod:`drake_skill.perception.pcae` and :mod:`drake_skill.perception.features`.

    [Station] --point_cloud--> [ObjectSegmenter] --object_points, valid--> [PcaeFeaturizer] --goal_data-->

## ObjectSegmenter

``ObjectSegmenter``: point cloud -> object cloud, bounding box, X_WO (docs/architecture.md, box ObjectSegmenter).

A thin Drake wrapper over :mod:`drake_skill.perception.segmentation` (docs/method.md section 3,
thesis sections 3.6 and 6.4), which documents the method.

Timing: computed on output evaluation, cached. The segmentation of the
current input cloud is a cache entry that depends only on the ``point_cloud``
input and the table plane held in the state, so every output of one frame
shares one computation, and an output evaluated right after the station's
camera frame (e.g. after ``AdvanceTo(0)``, to latch X_WO at the start of a
rollout) sees that frame. The station's cloud also depends on the plant's
state, so an evaluation after every plant step would segment again each
time; the consumers (``PcaeFeaturizer``, the DMP's latch) read at the camera
rate or once.

Per-run data live in the context's discrete state, updated by a periodic
*discrete* update every ``period_s`` (the camera rate, 10 Hz). The station's
MultibodyPlant advances in an unrestricted update, which Drake applies
before it computes the discrete updates due at the same instant; so this
update and the ``PcaeFeaturizer``'s, both discrete, read the same (already
stepped) scene, and the camera renders and the cloud is segmented once per
frame for both. Groups:

- table plane (5): ``[stored, a, b, c, d]`` (world frame,
  ``a x + b y + c z + d = 0``, unit normal, z up). The configured plane, or,
  when none is configured, not stored until the first update that sees a
  frame in which the plane could be fitted (RANSAC seeded with ``seed``),
  then kept for the rest of the run: the table does not move. Until it is
  stored, each evaluation fits it on the current frame: on the optional
  input ``plane_point_cloud`` when it is connected (the station's full
  frame, when ``point_cloud`` is the object camera's crop: the plane is then
  the full frame's, as the segmentation is, so the crop changes nothing the
  system computes; that cloud is evaluated only until the plane is stored),
  else on ``point_cloud``.
- held (1 + 1 + 3 + 7 + 3 n_points): ``[stored, yaw, position (3),
  bounding_box (7), object_points (n_points x 3, row-major)]``, the last
  valid frame's outputs (as of the latest update).

Outputs, for the current frame when it is valid, otherwise the held ones
(or the defaults before any valid frame):

- ``object_points`` (abstract ``Value[object]`` holding a float64 numpy array
  (n_points, 3) = (2048, 3), world frame, m): the segment resampled
  uniformly with the fixed ``seed`` (zeros before any valid frame);
- ``bounding_box`` (vector 7): ``[cx, cy, cz, ex, ey, ez, yaw]``, centre
  (m, world), extents (m) along the box's x, y (world x, y rotated by yaw
  about z) and z, and yaw (rad) of all the segment's points (zeros before
  any valid frame);
- ``X_WO`` (abstract ``RigidTransform``): the object frame O estimated from
  the box: origin at the centre of the footprint of the object's base on the
  table (the centre of its bottom face, as the station's O), z up, yaw of
  the footprint's sides nearest the nominal yaw (see
  :func:`drake_skill.perception.segmentation.estimate_box`). Before any valid frame:
  ``default_pose``;
- ``valid`` (vector 1): 1 when the current frame's largest cluster has at
  least ``min_points`` points, else 0 (object hidden by the arm, out of
  view or not found; the other outputs then hold the last valid frame);
- ``pixels`` (abstract ``SegmentPixels``): the current frame's colour image
  and its masks of the object's hue, object-coloured and kept pixels
  (:meth:`ObjectSegmenter.eval_pixels`; for recordings, which log it per frame).

Input ``point_cloud`` (abstract ``PointCloud`` with xyz and rgb, world frame,
organised as an ``image_height`` x ``image_width`` image, row-major; missing
returns non-finite): the station's ``object_point_cloud`` port (the camera
cropped to where the object can appear, ``drake_skill.station.camera``) or
its full-frame ``point_cloud``. A cloud of another
size or without colours raises ValueError: that is a wiring error, not an
empty segmentation.

Resetting the context to its defaults starts over (no plane, nothing held);
the same seed and the same frames give the same outputs.


## PcaeFeaturizer

``PcaeFeaturizer``: object cloud -> PCAE code -> goal data (docs/architecture.md, box PcaeFeaturizer).

A thin Drake wrapper over :mod:`drake_skill.perception.pcae` (the encoder, docs/method.md
section 3, thesis 3.5) and :mod:`drake_skill.perception.features` (the per-skill
PCA, thesis 6.4). Every ``period_s`` seconds (10 Hz by default, thesis 6.4)
a periodic discrete update reads one frame:

- if ``valid`` > 0.5 and ``object_points`` is connected, the cloud is
  expressed in the object frame when ``X_WO`` is connected (``p_O = R_WO^T
  (p_W - p_WO)``, :func:`~drake_skill.perception.pcae.cloud_in_object_frame`,
  with the X_WO latched at the run's first valid frame, as the DMP's frame
  is), then encoded (eval mode, ``torch.inference_mode``, ``n_threads`` torch threads) and the
  code, its goal data ``g = PCA(code)`` and ``goal_valid = 1`` are stored;
- otherwise the last valid code and goal data are held and ``goal_valid = 0``
  marks the frame (before the first valid frame both are zeros).

Per-run data live in the context's discrete state (``code`` (128),
``goal_data`` (k), ``flags`` (2: goal_valid of the latest frame, 1 once any
frame was valid), ``X_WO`` (12: R_WO row-major then p_WO [m], latched at the
first valid frame)); resetting the context to its defaults starts over. The
weights and the PCA are construction-time constants.

Ports:

- input ``object_points`` (abstract, ``Value[object]`` holding a numpy array
  (2048, 3), metres, world frame: the segmented object cloud, resampled to
  2048 points). An upstream output must be declared with the same value type,
  e.g. ``DeclareAbstractOutputPort("object_points", lambda: AbstractValue.Make(np.zeros((2048, 3))), calc)``;
- input ``valid`` (vector 1; optional, every frame valid when unconnected);
- input ``X_WO`` (abstract RigidTransform; optional: the perceived object
  pose, e.g. ``ObjectSegmenter``'s; unconnected, the clouds are encoded in
  the world frame, the thesis's form and that of skills with
  ``cloud_frame: world``);
- output ``code`` (vector 128): latest valid PCAE code (dimensionless);
- output ``goal_data`` (vector k = 8): PCA of that code (dimensionless; zeros
  if no PCA was given, as when recording demonstrations before fitting it);
- output ``goal_valid`` (vector 1): 1 when the latest frame was valid and a
  PCA was given, else 0.

The outputs depend only on the state (no direct feedthrough), so a system
sampling them at the same instants (e.g. ``PomrpReward`` at 10 Hz, offset 0)
sees the frame of the previous period; ``offset_s`` shifts this system's
updates if that matters.

"""

import dataclasses as dc
import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.common.value import AbstractValue, Value
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.perception import PointCloud
from pydrake.systems.framework import LeafSystem, ValueProducer

from drake_skill import typed_yaml
from drake_skill.perception.features import GoalFeatures
from drake_skill.perception.pcae import (CODE_SIZE, N_POINTS, PointCloudAutoencoder, check_points,
                                         cloud_in_object_frame, load_pcae)
from drake_skill.perception.segmentation import (
    BOUNDING_BOX_SIZE,
    SegmentationConfig,
    SegmentPixels,
    fit_table_plane,
    process_frame,
    segment_pixels,
)

__all__ = ["ObjectSegmenter", "ObjectSegmenterConfig", "add_object_segmenter", "segmenter_config_for_station",
           "PcaeFeaturizerConfig", "PcaeFeaturizer"]


@dc.dataclass
class ObjectSegmenterConfig:
    """Configuration of :class:`ObjectSegmenter` (loadable with ``yaml_load_typed``).

    period_s, offset_s: period and first time of the state update [s] (the camera rate).
    n_points: points of ``object_points`` (2048, docs/method.md section 3).
    seed: seeds the resampling and the table-plane RANSAC.
    image_width, image_height: the organised cloud's image size [pixels].
    plane_image_width, plane_image_height: image size of the optional
      ``plane_point_cloud`` input the table plane is fitted on [pixels].
    table_plane: ``[a, b, c, d]`` of the table in the world frame, or empty to
      fit it on the first frames (see the module docstring).
    default_pose: ``[x, y, yaw]`` [m, m, rad] of X_WO before any valid frame.
    segmentation: thresholds, see :class:`~drake_skill.perception.segmentation.SegmentationConfig`.
    """

    period_s: float = 0.1
    offset_s: float = 0.0
    n_points: int = N_POINTS
    seed: int = 0
    image_width: int = 640
    image_height: int = 480
    plane_image_width: int = 640
    plane_image_height: int = 480
    table_plane: list[float] = dc.field(default_factory=list)
    default_pose: list[float] = dc.field(default_factory=lambda: [0.55, 0.0, 0.0])
    segmentation: SegmentationConfig = dc.field(default_factory=SegmentationConfig)

    def validate(self) -> "ObjectSegmenterConfig":
        """Raises ValueError naming the field that cannot work; returns self."""
        bad = functools.partial(typed_yaml.bad, "object segmenter config")

        if not (math.isfinite(self.period_s) and self.period_s > 0):
            bad("period_s", self.period_s, "a positive period [s]")
        if not (math.isfinite(self.offset_s) and self.offset_s >= 0):
            bad("offset_s", self.offset_s, "a non-negative offset [s]")
        if self.n_points < 1:
            bad("n_points", self.n_points, "a positive number of points")
        if self.image_width < 1 or self.image_height < 1:
            bad("image_width/image_height", (self.image_width, self.image_height), "positive pixel counts")
        if self.plane_image_width < 1 or self.plane_image_height < 1:
            bad("plane_image_width/plane_image_height", (self.plane_image_width, self.plane_image_height),
                "positive pixel counts")
        if len(self.table_plane) not in (0, 4) or not all(math.isfinite(v) for v in self.table_plane):
            bad("table_plane", self.table_plane, "[] (fit it) or 4 finite coefficients [a, b, c, d]")
        if len(self.table_plane) == 4 and math.hypot(*self.table_plane[:3]) < 1e-9:
            bad("table_plane", self.table_plane, "a non-zero normal [a, b, c]")
        if len(self.default_pose) != 3 or not all(math.isfinite(v) for v in self.default_pose):
            bad("default_pose", self.default_pose, "[x, y, yaw] in m, m, rad")
        self.segmentation.validate()
        return self


def segmenter_config_for_station(station_config, window=None) -> ObjectSegmenterConfig:
    """The segmenter's configuration matching a ``Scenario``: image size,
    camera rate, the object's nominal pose (default X_WO, nominal yaw) and its
    footprint band (``object.footprint_heights``, where the scenario gives one).

    The image size is the full frame's, or that of ``window`` (a
    :class:`~drake_skill.station.camera.CropWindow`, the station's
    ``object_camera.window``) for the cropped object camera."""
    cam, obj = station_config.camera, station_config.object
    width, height = (cam.width, cam.height) if window is None else (window.width, window.height)
    config = ObjectSegmenterConfig(period_s=1.0 / cam.fps, image_width=width, image_height=height,
                                   plane_image_width=cam.width, plane_image_height=cam.height,
                                   default_pose=[obj.x, obj.y, obj.yaw])
    config.segmentation.nominal_yaw = obj.yaw
    colour = obj.colour
    config.segmentation.hue_min_deg, config.segmentation.hue_max_deg = colour.hue_min_deg, colour.hue_max_deg
    config.segmentation.saturation_min, config.segmentation.value_min = colour.saturation_min, colour.value_min
    config.segmentation.cluster_rule = colour.cluster_rule
    if obj.footprint_heights:
        config.segmentation.footprint_min_height, config.segmentation.footprint_max_height = obj.footprint_heights
    return config.validate()


@dc.dataclass(frozen=True)
class _Estimate:
    """Outputs of one frame: points (n, 3), bounding box (7,), X_WO as position (3,) and yaw."""

    points: np.ndarray
    bounding_box: np.ndarray
    position: np.ndarray
    yaw: float

    def to_vector(self) -> np.ndarray:
        """The held-state layout: [1, yaw, position (3), bounding box (7), points (3 n)]."""
        return np.concatenate([[1.0, self.yaw], self.position, self.bounding_box, self.points.ravel()])

    @classmethod
    def from_vector(cls, v: np.ndarray, n_points: int) -> "_Estimate | None":
        if v[0] < 0.5:
            return None
        points = np.array(v[12:], dtype=np.float64).reshape(n_points, 3)   # a copy: the state changes
        return cls(points, np.array(v[5:12]), np.array(v[2:5]), float(v[1]))


@dc.dataclass(frozen=True)
class _Frame:
    """Cached result of the current input: the estimate (None if not valid),
    the plane used (None if it could not be fitted) and the full
    :class:`~drake_skill.perception.segmentation.FrameResult` (None without a plane)."""

    estimate: _Estimate | None
    plane: np.ndarray | None
    result: object | None


class ObjectSegmenter(LeafSystem):
    """Segments the known-colour object from the station's cloud (see the module docstring)."""

    def __init__(self, config: ObjectSegmenterConfig | None = None):
        super().__init__()
        config = (config if config is not None else ObjectSegmenterConfig()).validate()
        self._config = config
        self._image_shape = (config.image_height, config.image_width)
        x, y, yaw = config.default_pose
        self._default_X_WO = RigidTransform(RotationMatrix.MakeZRotation(yaw), [x, y, 0.0])

        self._cloud_port = self.DeclareAbstractInputPort("point_cloud", Value(PointCloud()))
        self._plane_cloud_port = self.DeclareAbstractInputPort("plane_point_cloud", Value(PointCloud()))
        plane0 = np.zeros(5)
        if config.table_plane:
            plane = np.asarray(config.table_plane, dtype=float)
            plane0[0], plane0[1:] = 1.0, plane / np.linalg.norm(plane[:3]) * (1.0 if plane[2] >= 0 else -1.0)
        n = config.n_points
        self._plane_index = self.DeclareDiscreteState(plane0)
        self._held_index = self.DeclareDiscreteState(np.zeros(12 + 3 * n))
        self.DeclarePeriodicDiscreteUpdateEvent(config.period_s, config.offset_s, self._update_memory)

        self._frame_cache = self.DeclareCacheEntry(
            "segmentation of the current point cloud",
            ValueProducer(allocate=lambda: AbstractValue.Make(None), calc=self._calc_frame),
            {self._cloud_port.ticket(), self._plane_cloud_port.ticket(),
             self.discrete_state_ticket(self._plane_index)},
        )
        deps = {self._frame_cache.ticket(), self.discrete_state_ticket(self._held_index)}
        self._points_port = self.DeclareAbstractOutputPort(
            "object_points", lambda: AbstractValue.Make(np.zeros((n, 3))), self._calc_points, deps)
        self._box_port = self.DeclareVectorOutputPort(
            "bounding_box", BOUNDING_BOX_SIZE, self._calc_box, deps)
        self._X_WO_port = self.DeclareAbstractOutputPort(
            "X_WO", lambda: Value(RigidTransform()), self._calc_X_WO, deps)
        self._valid_port = self.DeclareVectorOutputPort(
            "valid", 1, self._calc_valid, {self._frame_cache.ticket()})
        self._pixels_port = self.DeclareAbstractOutputPort(
            "pixels", lambda: AbstractValue.Make(object()), self._calc_pixels,
            {self._frame_cache.ticket(), self._cloud_port.ticket()})

    # ---------------------------------------------------------------- ports
    @property
    def config(self) -> ObjectSegmenterConfig:
        return self._config

    def get_point_cloud_input_port(self):
        return self._cloud_port

    def get_plane_point_cloud_input_port(self):
        return self._plane_cloud_port

    def get_object_points_output_port(self):
        return self._points_port

    def get_bounding_box_output_port(self):
        return self._box_port

    def get_X_WO_output_port(self):
        return self._X_WO_port

    def get_valid_output_port(self):
        return self._valid_port

    def get_pixels_output_port(self):
        return self._pixels_port

    # ------------------------------------------------------------ inspection
    def eval_frame(self, context):
        """The current frame's :class:`~drake_skill.perception.segmentation.FrameResult` (its
        ``segmentation`` holds the object's pixels before resampling), or None
        when no table plane is available yet."""
        return self._frame_cache.Eval(context).result

    def eval_pixels(self, context) -> SegmentPixels:
        """The current frame's colour image and its pixels of the object's hue, object-coloured and
        kept by the segment (:func:`~drake_skill.perception.segmentation.segment_pixels`; nothing
        kept before the table plane is known): the ``pixels`` output, which a recording's frame log
        (``drake_skill.station.loggers.FrameLog``) counts and keeps at every frame."""
        _, rgb = self._read_cloud(context)
        result = self.eval_frame(context)
        return segment_pixels(rgb, self._config.segmentation, self._image_shape,
                              None if result is None else result.segmentation)

    def table_plane(self, context) -> np.ndarray | None:
        """The table plane stored in ``context`` (None until it has been fitted)."""
        plane = context.get_discrete_state(self._plane_index).get_value()
        return np.array(plane[1:]) if plane[0] > 0.5 else None

    # ------------------------------------------------------------ callbacks
    def _read_cloud(self, context) -> tuple[np.ndarray, np.ndarray]:
        cloud = self._cloud_port.Eval(context)
        h, w = self._image_shape
        if cloud.size() != h * w:
            raise ValueError(f"point_cloud: {cloud.size()} points, expected an organised "
                             f"{h}x{w} cloud ({h * w} points); set image_width/image_height")
        if not (cloud.has_xyzs() and cloud.has_rgbs()):
            raise ValueError("point_cloud: expected xyz and rgb fields (BaseField.kXYZs | kRGBs)")
        return cloud.xyzs().T, cloud.rgbs().T     # (P, 3) views, no copy

    def _fit_plane(self, context, xyz) -> np.ndarray:
        """The table plane fitted on ``plane_point_cloud`` when connected, else on ``xyz``."""
        cfg, shape = self._config, self._image_shape
        if self._plane_cloud_port.HasValue(context):
            cloud = self._plane_cloud_port.Eval(context)
            shape = (cfg.plane_image_height, cfg.plane_image_width)
            if cloud.size() != shape[0] * shape[1] or not cloud.has_xyzs():
                raise ValueError(f"plane_point_cloud: {cloud.size()} points, expected an organised "
                                 f"{shape[0]}x{shape[1]} cloud with xyz; set plane_image_width/height")
            xyz = cloud.xyzs().T
        return fit_table_plane(xyz, cfg.segmentation, shape, seed=cfg.seed)

    def _calc_frame(self, context, value):
        xyz, rgb = self._read_cloud(context)
        cfg = self._config
        stored = context.get_discrete_state(self._plane_index).get_value()
        if stored[0] > 0.5:
            plane = np.array(stored[1:])
        else:
            try:
                plane = self._fit_plane(context, xyz)
            except ValueError:        # blank frame, table hidden: no plane yet, not valid
                value.set_value(_Frame(None, None, None))
                return
        result = process_frame(xyz, rgb, plane, cfg.segmentation, self._image_shape,
                               n_points=cfg.n_points, seed=cfg.seed)
        estimate = None
        if result.valid:
            for a in (result.points, result.box.bounding_box, result.box.position):
                a.setflags(write=False)
            estimate = _Estimate(result.points, result.box.bounding_box, result.box.position,
                                 float(result.box.yaw))
        value.set_value(_Frame(estimate, plane, result))

    def _update_memory(self, context, discrete_state):
        frame = self._frame_cache.Eval(context)
        if frame.plane is not None and context.get_discrete_state(self._plane_index).get_value()[0] < 0.5:
            discrete_state.get_mutable_vector(self._plane_index).SetFromVector(np.r_[1.0, frame.plane])
        if frame.estimate is not None:
            discrete_state.get_mutable_vector(self._held_index).SetFromVector(frame.estimate.to_vector())

    def _estimate(self, context) -> _Estimate | None:
        estimate = self._frame_cache.Eval(context).estimate
        if estimate is None:
            estimate = _Estimate.from_vector(context.get_discrete_state(self._held_index).get_value(),
                                             self._config.n_points)
        return estimate

    def _calc_points(self, context, output):
        estimate = self._estimate(context)
        output.set_value(estimate.points if estimate is not None else np.zeros((self._config.n_points, 3)))

    def _calc_box(self, context, output):
        estimate = self._estimate(context)
        output.SetFromVector(estimate.bounding_box if estimate is not None else np.zeros(BOUNDING_BOX_SIZE))

    def _calc_X_WO(self, context, output):
        estimate = self._estimate(context)
        if estimate is None:
            output.set_value(self._default_X_WO)
        else:
            output.set_value(RigidTransform(RotationMatrix.MakeZRotation(estimate.yaw), estimate.position))

    def _calc_pixels(self, context, output):
        output.set_value(self.eval_pixels(context))

    def _calc_valid(self, context, output):
        output.SetFromVector([1.0 if self._frame_cache.Eval(context).estimate is not None else 0.0])


def add_object_segmenter(builder, station, config: ObjectSegmenterConfig | None = None,
                         name: str = "object_segmenter") -> ObjectSegmenter:
    """Adds an :class:`ObjectSegmenter` to ``builder`` and connects the station's cloud to it.

    The cloud is the station's cropped ``object_point_cloud`` when the station has
    an object camera (``station.object_camera``) and ``config`` is None or sized
    for its window, with the full-frame ``point_cloud`` on ``plane_point_cloud``
    for the table plane; else the full-frame ``point_cloud``. ``config`` defaults to
    :func:`segmenter_config_for_station` of ``station.config`` for that cloud.
    """
    camera = station.object_camera
    if config is None:
        config = segmenter_config_for_station(station.config, camera.window if camera is not None else None)
    segmenter = builder.AddNamedSystem(name, ObjectSegmenter(config))
    if camera is not None and (config.image_height, config.image_width) == camera.window.shape:
        builder.Connect(station.GetOutputPort(camera.cloud_port_name), segmenter.get_point_cloud_input_port())
        # The table plane from the full frame, as without the crop (rendered until the
        # plane is stored: on the run's first frame).
        builder.Connect(station.GetOutputPort("point_cloud"), segmenter.get_plane_point_cloud_input_port())
    else:
        builder.Connect(station.GetOutputPort("point_cloud"), segmenter.get_point_cloud_input_port())
    return segmenter


# -------------------------------------------------------------------------- PcaeFeaturizer


@dataclass
class PcaeFeaturizerConfig:
    """Configuration of :class:`PcaeFeaturizer` (loadable with ``yaml_load_typed``)."""

    period_s: float = 0.1
    """Seconds between frames (thesis: 10 Hz)."""
    offset_s: float = 0.0
    """Time of the first update (s)."""
    weights: str = ""
    """PCAE safetensors file; empty means the shipped ``models/pcae.safetensors``."""
    n_threads: int = 1
    """Torch threads used by one encoding."""
    n_goal: int = 8
    """Size of ``goal_data`` when no PCA is given (otherwise the PCA's n_components)."""


class PcaeFeaturizer(LeafSystem):
    """Encodes the object cloud at a fixed rate; see the module docstring for ports and state."""

    def __init__(self, goal_features: GoalFeatures | None = None, config: PcaeFeaturizerConfig | None = None,
                 model: PointCloudAutoencoder | None = None):
        super().__init__()
        config = config if config is not None else PcaeFeaturizerConfig()
        if not (np.isfinite(config.period_s) and config.period_s > 0):
            raise ValueError(f"config.period_s: expected a finite period > 0 s, got {config.period_s}")
        if not (np.isfinite(config.offset_s) and config.offset_s >= 0):
            raise ValueError(f"config.offset_s: expected a finite offset >= 0 s, got {config.offset_s}")
        if int(config.n_threads) < 1:
            raise ValueError(f"config.n_threads: expected >= 1, got {config.n_threads}")
        if goal_features is not None:
            goal_features._check_fitted()
            if goal_features.n_features != CODE_SIZE:
                raise ValueError(f"goal_features: fitted on {goal_features.n_features}-D codes, expected {CODE_SIZE}")
        n_goal = goal_features.n_components if goal_features is not None else int(config.n_goal)
        if n_goal < 1:
            raise ValueError(f"config.n_goal: expected >= 1, got {config.n_goal}")
        if model is None:
            model = load_pcae(Path(config.weights) if config.weights else None)
        model.eval()
        # Construction-time constants (never per-run data).
        self._config = config
        self._model = model
        self._pca = goal_features

        self._points_port = self.DeclareAbstractInputPort("object_points", AbstractValue.Make(np.zeros((N_POINTS, 3))))
        self._valid_port = self.DeclareVectorInputPort("valid", 1)
        self._X_WO_port = self.DeclareAbstractInputPort("X_WO", Value(RigidTransform()))

        self._code_index = self.DeclareDiscreteState(CODE_SIZE)
        self._X_WO_index = self.DeclareDiscreteState(np.concatenate([np.eye(3).ravel(), np.zeros(3)]))
        self._goal_index = self.DeclareDiscreteState(n_goal)
        self._flags_index = self.DeclareDiscreteState(2)
        self.DeclarePeriodicDiscreteUpdateEvent(config.period_s, config.offset_s, self._update_frame)

        xd = {self.xd_ticket()}
        self._code_port = self.DeclareVectorOutputPort("code", CODE_SIZE, self._calc_code, xd)
        self._goal_port = self.DeclareVectorOutputPort("goal_data", n_goal, self._calc_goal, xd)
        self._goal_valid_port = self.DeclareVectorOutputPort("goal_valid", 1, self._calc_goal_valid, xd)

    # ---------------------------------------------------------------- ports
    def get_object_points_input_port(self):
        return self._points_port

    def get_valid_input_port(self):
        return self._valid_port

    def get_X_WO_input_port(self):
        return self._X_WO_port

    def get_code_output_port(self):
        return self._code_port

    def get_goal_data_output_port(self):
        return self._goal_port

    def get_goal_valid_output_port(self):
        return self._goal_valid_port

    @property
    def config(self) -> PcaeFeaturizerConfig:
        return self._config

    def has_valid_frame(self, context) -> bool:
        """True once any frame of this run was valid (read from ``context``)."""
        return bool(context.get_discrete_state(self._flags_index).get_value()[1] > 0.5)

    # ------------------------------------------------------------- update
    def _frame_is_valid(self, context) -> bool:
        if self._valid_port.HasValue(context):
            v = float(self._valid_port.Eval(context)[0])
            if not np.isfinite(v):
                raise ValueError(f"PcaeFeaturizer: input 'valid' is {v} at t = {context.get_time():.3f} s, "
                                 "expected 0 or 1")
            if v <= 0.5:
                return False
        return self._points_port.HasValue(context)

    def _update_frame(self, context, discrete_state):
        flags = discrete_state.get_mutable_vector(self._flags_index)
        if not self._frame_is_valid(context):
            flags.SetAtIndex(0, 0.0)  # code and goal data are held
            return
        points = self._points_port.Eval(context)
        try:
            pts = check_points(points, "object_points", N_POINTS)
        except ValueError as e:
            raise ValueError(f"PcaeFeaturizer at t = {context.get_time():.3f} s: {e} "
                             "(world-frame cloud in metres)") from e
        if self._X_WO_port.HasValue(context):
            X_state = discrete_state.get_mutable_vector(self._X_WO_index)
            if context.get_discrete_state(self._flags_index).get_value()[1] < 0.5:   # the run's first valid frame
                X = self._X_WO_port.Eval(context)
                X_state.SetFromVector(np.concatenate([X.rotation().matrix().ravel(), X.translation()]))
            x = X_state.get_value()
            X_WO = np.eye(4)
            X_WO[:3, :3], X_WO[:3, 3] = x[:9].reshape(3, 3), x[9:]
            pts = cloud_in_object_frame(pts, X_WO)
        code = self._model.encode_points(pts, n_threads=self._config.n_threads)
        discrete_state.get_mutable_vector(self._code_index).SetFromVector(code.astype(np.float64))
        if self._pca is not None:
            discrete_state.get_mutable_vector(self._goal_index).SetFromVector(self._pca.transform(code))
        flags.SetFromVector([1.0 if self._pca is not None else 0.0, 1.0])

    # ------------------------------------------------------------- outputs
    def _calc_code(self, context, output):
        output.SetFromVector(context.get_discrete_state(self._code_index).get_value())

    def _calc_goal(self, context, output):
        output.SetFromVector(context.get_discrete_state(self._goal_index).get_value())

    def _calc_goal_valid(self, context, output):
        output.SetAtIndex(0, context.get_discrete_state(self._flags_index).get_value()[0])
