"""The reward boxes of the diagram (docs/architecture.md): the ``PomrpReward``
LeafSystem over :mod:`drake_skill.reward.pomrp`, and the goal pipeline that wires
segmenter -> featurizer -> reward behind a station.

## PomrpReward

``PomrpReward``: the learned-reward box of the diagram (docs/architecture.md; docs/method.md section 4).

A thin Drake wrapper around :class:`drake_skill.reward.pomrp.Pomrp`.  Every
``period`` seconds (10 Hz by default) it reads one frame of goal data and, if
the frame is valid, appends it to the execution's sequence and advances the
log-space forward filter.  Everything per-run lives in the context's discrete
state, so resetting the context to its defaults starts a new execution
(``SetDefaultContext`` keeps the time: set it back to 0 as well, or the first
periodic update comes at the old time).

Ports:
  * input ``goal_data`` (vector ``d``, 8 in the project): ``g_t``, unitless;
  * input ``valid`` (vector 1; optional): frames with ``valid <= 0.5`` are
    skipped; when unconnected every frame is valid;
  * output ``reward`` (vector 1): filtered reward of the latest valid frame,
    ``sum_s v(s) P(s_t = s | g_1..g_t)`` (0 before the first frame);
  * output ``return`` (vector 1): running sum of those rewards.

At the end of a rollout, :meth:`goal_sequence`, :meth:`filtered_rewards`
(the online rewards, kept per frame), :meth:`smoothed_return` (Eq. 4.5 with
smoothed posteriors, which need the whole sequence) and :meth:`verdict` read
the result. Each reward is computed once: the filtered one here, online; the
smoothed one offline from the goal sequence (``RolloutRunner``).

A frame it cannot take stops the simulator as Drake's monitors do: the
update returns ``EventStatus.ReachedTermination`` and keeps the reason in
state ([code, time [s], index, value]: non-finite goal data, which element and its value, or
more valid frames than ``capacity``); :meth:`PomrpReward.stop_error` gives it
as the typed error (:class:`NonFiniteGoalData`, :class:`RewardCapacityError`),
which ``drake_skill.station.recording.advance_station`` raises outside the
simulator.


## The goal pipeline

The perception-to-reward chain of docs/architecture.md, wired behind a station.

    [Station] --object_point_cloud--> [ObjectSegmenter] --object_points, valid--> [PcaeFeaturizer]
              --goal_data, goal_valid--> [PomrpReward] --> reward, return

``add_goal_pipeline(builder, station, skill)`` adds the three systems of a
fitted :class:`~drake_skill.fitted_skill.Skill` (its PCAE weights, PCA and POMRP) and
connects them by their named ports; the segmenter reads the station's
object camera (the camera cropped to where the object can appear,
``drake_skill.station.camera``). Each samples at the camera rate
(``station.config.camera.fps``, 10 Hz), and the camera renders and the
segmenter segments once per frame for both the segmenter's memory and the
featurizer (both are discrete updates, after the plant's step). The reward system reads the goal data
the featurizer stored at the previous frame, so the reward lags the camera by
one frame (0.1 s); the thesis' returns are sums over whole executions, which a
short settle time at the end covers.

"""

import dataclasses as dc
from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import Context, DiscreteValues, EventStatus, LeafSystem

from drake_skill.perception.systems import ObjectSegmenter, PcaeFeaturizer, PcaeFeaturizerConfig, add_object_segmenter
from drake_skill.reward.pomrp import Pomrp

__all__ = ["NonFiniteGoalData", "RewardCapacityError", "PomrpRewardConfig", "PomrpReward", "GoalPipeline",
           "add_goal_pipeline"]


@dataclass
class PomrpRewardConfig:
    """Attributes:
      period: seconds between goal-data frames (thesis: 10 Hz).
      capacity: most frames one execution may keep (default 60 s at 10 Hz).
    """

    period: float = 0.1
    capacity: int = 600


class NonFiniteGoalData(ValueError):
    """A valid frame's goal data is not finite (a rollout's failure reason "non_finite")."""

    reason = "non_finite"


class RewardCapacityError(RuntimeError):
    """More valid frames than ``PomrpRewardConfig.capacity`` (a configuration error; reason "error")."""


# The stop codes kept in PomrpReward's state (0: running).
_STOP_NON_FINITE, _STOP_CAPACITY = 1, 2


class PomrpReward(LeafSystem):
    """Streams goal data through the POMRP; see the module docstring for ports."""

    def __init__(self, pomrp: Pomrp, config: PomrpRewardConfig | None = None):
        super().__init__()
        config = config if config is not None else PomrpRewardConfig()
        if not config.period > 0:
            raise ValueError(f"config.period: expected > 0 s, got {config.period}")
        if int(config.capacity) < 1:
            raise ValueError(f"config.capacity: expected >= 1 frame, got {config.capacity}")
        self._pomrp = pomrp
        self._config = config
        self._d = d = pomrp.n_features
        self._k = k = pomrp.n_states
        self._capacity = int(config.capacity)

        self._goal_port = self.DeclareVectorInputPort("goal_data", d)
        self._valid_port = self.DeclareVectorInputPort("valid", 1)
        # Per-run state: frame count; filter (log belief (k), log P(g_1..g_t),
        # last reward, running return); the frames themselves (capacity x d); each
        # frame's filtered reward (capacity).
        self._count_index = self.DeclareDiscreteState(1)
        self._filter_index = self.DeclareDiscreteState(k + 3)
        self._frames_index = self.DeclareDiscreteState(self._capacity * d)
        self._rewards_index = self.DeclareDiscreteState(self._capacity)
        self._stop_index = self.DeclareDiscreteState(4)     # [stop code, time [s], element index, value]
        self.DeclarePeriodicDiscreteUpdateEvent(config.period, 0.0, self._update)
        xd = {self.xd_ticket()}
        self._reward_port = self.DeclareVectorOutputPort("reward", 1, self._calc_reward, xd)
        self._return_port = self.DeclareVectorOutputPort("return", 1, self._calc_return, xd)

    @property
    def pomrp(self) -> Pomrp:
        return self._pomrp

    def get_goal_data_input_port(self):
        return self._goal_port

    def get_valid_input_port(self):
        return self._valid_port

    def get_reward_output_port(self):
        return self._reward_port

    def get_return_output_port(self):
        return self._return_port

    # ---------------------------------------------------------------- update
    def _update(self, context: Context, discrete_state: DiscreteValues):
        if self._valid_port.HasValue(context) and self._valid_port.Eval(context)[0] <= 0.5:
            return EventStatus.DidNothing()
        g = np.array(self._goal_port.Eval(context), dtype=float)
        n = int(context.get_discrete_state(self._count_index).GetAtIndex(0))
        if not np.all(np.isfinite(g)):
            i = int(np.flatnonzero(~np.isfinite(g))[0])
            return self._stop(context, discrete_state, [_STOP_NON_FINITE, context.get_time(), i, g[i]])
        if n >= self._capacity:
            return self._stop(context, discrete_state, [_STOP_CAPACITY, context.get_time(), n, 0.0])
        k = self._k
        f = context.get_discrete_state(self._filter_index).get_value()
        previous = None      # the frame before g (the progress reward's Phi_(t-1))
        if n > 0:
            previous = context.get_discrete_state(self._frames_index).get_value()[(n - 1) * self._d:n * self._d]
        log_belief, step_ll, reward = self._pomrp.filter_update(f[:k], g, first=(n == 0), previous=previous)
        new_f = np.empty(k + 3)
        new_f[:k] = log_belief
        new_f[k] = (f[k] if n > 0 else 0.0) + step_ll
        new_f[k + 1] = reward
        new_f[k + 2] = (f[k + 2] if n > 0 else 0.0) + reward
        discrete_state.get_mutable_vector(self._filter_index).SetFromVector(new_f)
        frames = discrete_state.get_mutable_vector(self._frames_index)
        for i in range(self._d):
            frames.SetAtIndex(n * self._d + i, g[i])
        discrete_state.get_mutable_vector(self._rewards_index).SetAtIndex(n, reward)
        discrete_state.get_mutable_vector(self._count_index).SetAtIndex(0, n + 1)
        return EventStatus.Succeeded()

    def _stop(self, context: Context, discrete_state: DiscreteValues, stop: list):
        discrete_state.get_mutable_vector(self._stop_index).SetFromVector(stop)
        return EventStatus.ReachedTermination(self, "PomrpReward: a frame it cannot take (see stop_error)")

    def stop_error(self, context: Context) -> RuntimeError | None:
        """Why this system stopped the simulator in ``context`` (its own or a root context), as
        the typed error, or None while it runs."""
        context = self._own(context)
        code, t, i, value = context.get_discrete_state(self._stop_index).get_value()
        if code == _STOP_NON_FINITE:
            return NonFiniteGoalData(
                f"PomrpReward: goal_data[{int(i)}] = {value} at t = {t:.3f} s while valid; "
                "expected finite goal data, or valid = 0 for frames without it")
        if code == _STOP_CAPACITY:
            return RewardCapacityError(
                f"PomrpReward: more than capacity = {self._capacity} valid frames at "
                f"t = {t:.3f} s; raise PomrpRewardConfig.capacity")
        return None

    def _calc_reward(self, context: Context, output):
        output.SetAtIndex(0, context.get_discrete_state(self._filter_index).GetAtIndex(self._k + 1))

    def _calc_return(self, context: Context, output):
        output.SetAtIndex(0, context.get_discrete_state(self._filter_index).GetAtIndex(self._k + 2))

    # --------------------------------------------------------------- readers
    def _own(self, context: Context) -> Context:
        """Accepts this system's context or a root (diagram) context holding it."""
        try:
            self.ValidateContext(context)
            return context
        except RuntimeError:
            return self.GetMyContextFromRoot(context)

    def goal_sequence(self, context: Context) -> np.ndarray:
        """The valid frames received so far, ``(n, d)`` (a copy)."""
        context = self._own(context)
        n = int(context.get_discrete_state(self._count_index).GetAtIndex(0))
        frames = context.get_discrete_state(self._frames_index).get_value()
        return np.array(frames[: n * self._d]).reshape(n, self._d)

    def filtered_rewards(self, context: Context) -> np.ndarray:
        """Each valid frame's filtered reward, as the ``reward`` output gave it, ``(n,)`` (a copy): the
        per-step rewards of the per-step methods (docs/method.md section 4), computed here once."""
        context = self._own(context)
        n = int(context.get_discrete_state(self._count_index).GetAtIndex(0))
        return np.array(context.get_discrete_state(self._rewards_index).get_value()[:n])

    def filtered_return(self, context: Context) -> float:
        """Running sum of the filtered per-step rewards (the ``return`` output)."""
        return float(self._own(context).get_discrete_state(self._filter_index).GetAtIndex(self._k + 2))

    def log_likelihood(self, context: Context) -> float:
        """``log P(g_1..g_n)`` of the frames so far (nats); 0 before any frame."""
        return float(self._own(context).get_discrete_state(self._filter_index).GetAtIndex(self._k))

    def smoothed_rewards(self, context: Context) -> np.ndarray:
        """Eq. 4.4 on the whole sequence, ``(n,)``; empty before any frame."""
        G = self.goal_sequence(context)
        return self._pomrp.rewards(G) if len(G) else np.zeros(0)

    def smoothed_return(self, context: Context) -> float:
        """Eq. 4.5 on the whole sequence (the black-box return); 0.0 before any frame."""
        G = self.goal_sequence(context)
        return self._pomrp.episode_return(G) if len(G) else 0.0

    def verdict(self, context: Context) -> bool:
        """The goal model's success verdict on the sequence; False before any frame."""
        G = self.goal_sequence(context)
        return self._pomrp.verdict(G) if len(G) else False


# -------------------------------------------------------------------------- goal pipeline


@dc.dataclass
class GoalPipeline:
    """Handles to the systems :func:`add_goal_pipeline` added."""

    segmenter: ObjectSegmenter
    featurizer: PcaeFeaturizer
    reward: PomrpReward


def add_goal_pipeline(builder, station, skill) -> GoalPipeline:
    """Adds segmenter -> featurizer -> reward for ``skill`` behind ``station``'s camera."""
    if not station.config.enable_camera:
        raise ValueError("the goal pipeline needs a station built with enable_camera = true")
    period = 1.0 / station.config.camera.fps
    segmenter = add_object_segmenter(builder, station)
    featurizer = builder.AddNamedSystem("pcae_featurizer", PcaeFeaturizer(
        skill.goal_features, PcaeFeaturizerConfig(period_s=period), model=skill.encoder()))
    reward = builder.AddNamedSystem("pomrp_reward", PomrpReward(skill.pomrp, PomrpRewardConfig(period=period)))
    builder.Connect(segmenter.get_object_points_output_port(), featurizer.get_object_points_input_port())
    builder.Connect(segmenter.get_valid_output_port(), featurizer.get_valid_input_port())
    if skill.config.cloud_frame == "object":
        builder.Connect(segmenter.get_X_WO_output_port(), featurizer.get_X_WO_input_port())
    builder.Connect(featurizer.get_goal_data_output_port(), reward.GetInputPort("goal_data"))
    builder.Connect(featurizer.get_goal_valid_output_port(), reward.GetInputPort("valid"))
    return GoalPipeline(segmenter, featurizer, reward)
