"""``PcaeFeaturizer``: object cloud -> PCAE code -> goal data (ARCHITECTURE.md, box PcaeFeaturizer).

A thin Drake wrapper over :mod:`drake_skill.pcae` (the encoder, METHOD.md
section 3, thesis 3.5) and :mod:`drake_skill.goal_features` (the per-skill
PCA, thesis 6.4). Every ``period_s`` seconds (10 Hz by default, thesis 6.4)
a periodic discrete update reads one frame:

- if ``valid`` > 0.5 and ``object_points`` is connected, the cloud is encoded
  (eval mode, ``torch.inference_mode``, ``n_threads`` torch threads) and the
  code, its goal data ``g = PCA(code)`` and ``goal_valid = 1`` are stored;
- otherwise the last valid code and goal data are held and ``goal_valid = 0``
  marks the frame (before the first valid frame both are zeros).

Per-run data live in the context's discrete state (``code`` (128),
``goal_data`` (k), ``flags`` (2: goal_valid of the latest frame, 1 once any
frame was valid)); resetting the context to its defaults starts over. The
weights and the PCA are construction-time constants.

Ports:

- input ``object_points`` (abstract, ``Value[object]`` holding a numpy array
  (2048, 3), metres, world frame: the segmented object cloud, resampled to
  2048 points). An upstream output must be declared with the same value type,
  e.g. ``DeclareAbstractOutputPort("object_points", lambda: AbstractValue.Make(np.zeros((2048, 3))), calc)``;
- input ``valid`` (vector 1; optional, every frame valid when unconnected);
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


from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from drake_skill.goal_features import GoalFeatures
from drake_skill.pcae import CODE_SIZE, DEFAULT_WEIGHTS, N_POINTS, PointCloudAutoencoder, check_points, load_pcae

__all__ = ["PcaeFeaturizerConfig", "PcaeFeaturizer"]


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

    def __init__(self, goal_features: GoalFeatures | None = None, config: PcaeFeaturizerConfig | None = None, model: PointCloudAutoencoder | None = None):
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
            model = load_pcae(Path(config.weights) if config.weights else DEFAULT_WEIGHTS)
        model.eval()
        # Construction-time constants (never per-run data).
        self._config = config
        self._model = model
        self._pca = goal_features

        self._points_port = self.DeclareAbstractInputPort("object_points", AbstractValue.Make(np.zeros((N_POINTS, 3))))
        self._valid_port = self.DeclareVectorInputPort("valid", 1)

        self._code_index = self.DeclareDiscreteState(CODE_SIZE)
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
                raise ValueError(f"PcaeFeaturizer: input 'valid' is {v} at t = {context.get_time():.3f} s, expected 0 or 1")
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
            raise ValueError(f"PcaeFeaturizer at t = {context.get_time():.3f} s: {e} (world-frame cloud in metres)") from e
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
