"""Plain imitation of one demonstration, on the demonstration's own object pose.

:func:`imitate` executes one DMP (typically the one fitted to ``demo``) in the
simulated station with the object where the demonstration had it, and
records at 100 Hz what the hand and the object did::

    imitator = Imitator(skill)                          # builds the station once per skill
    for dmp, demo in zip(skill.dmps, demos):
        im = imitator.imitate(dmp, demo)                # an Imitation
        im.X_OE_demo_grid                               # (T, 7) measured path on demo.times_100hz
        metrics = imitation_metrics(skill.config.dmp, dmp, demo, im)

The diagram is :class:`~drake_skill.learning.rollout.RolloutRunner`'s
(docs/architecture.md, "One diagram per skill execution") with
``RolloutConfig(object_pose="ground_truth", goal_model=False,
record_hz=100)``: the object frame O is the simulator's ground truth, so
perception noise does not enter, and no camera is needed (it is switched off
when the station config comes from the skill). The runner's reset places the
object at ``station.random_object_pose(demo.seed)``, which is the
demonstration's ``X_WO_true`` for every demonstration recorded in simulation
(``drake-skill demos record``, scripted or interactive); a demonstration whose
``X_WO_true`` differs (another scenario's randomisation, the robot) is
imitated at its ``X_WO_true`` instead. The DMP starts from the hand's
measured pose in O at reset (the home pose, where the demonstration started
too) with the DMP's own goal and duration tau, and runs tau plus the runner's
settle time.

A run the station stops (collision reflex, solver failure, divergence) is
kept up to where it stopped, with ``failed`` and ``reason``
(:data:`~drake_skill.learning.rollout.FAILURE_REASONS`).

This module imports Drake only when an :class:`Imitator` is built; the
figures of ``drake-skill bench imitation`` are plain numpy
(:mod:`drake_skill.action.metrics`).
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses as dc
import math
import time
from pathlib import Path

import numpy as np

from drake_skill.action import metrics
from drake_skill.action.dmp import Dmp, DmpConfig, integrate
from drake_skill.demos.format import object_frame_poses

__all__ = ["Imitation", "Imitator", "check_demo_pairs", "imitate", "imitation_metrics", "RECORD_HZ"]

#: Rate of an imitation's records [Hz]: the demonstrations' raw rate.
RECORD_HZ = 100.0
#: A demonstration's ``X_WO_true`` counts as the pose drawn from its seed within these [m], [-].
_POSE_MATCH_M = 1e-6
_POSE_MATCH_Q = 1e-9


@dc.dataclass
class Imitation:
    """One execution of a DMP on a demonstration's object pose (plain arrays).

    times: (N,) s, the grid k / 100 Hz from 0 over tau + settle time (fewer
      samples when the run stopped early).
    X_OE: (N, 7) the *measured* hand pose in the object frame O (xyz m +
      quaternion wxyz), as ``Demonstration.X_OE_100hz`` records it.
    X_OE_commanded: (N, 7) the DMP's commanded pose in O at the same instants
      (the DMP as executed: start = the measured hand pose at reset; held at
      its pose at tau afterwards, as ``DmpSystem`` does).
    object_state: (N,) lid angle [rad] or drawer travel [m]; contact_force:
      (N,) peak robot-scene contact force over each interval [N].
    failed / reason / message: the station stopped the run (``reason`` one of
      ``FAILURE_REASONS``: "reflex" for the collision reflex).
    success: ground-truth success of the run; final_object_state: the last
      recorded object state.
    X_WO: (7,) the object pose used; seed: the demonstration's seed.
    dmp: the DMP as executed (its y0 the measured start).
    demo_times: (T,) the demonstration's ``times_100hz`` (s), for
      :attr:`X_OE_demo_grid`.
    """

    skill: str
    demo: str
    seed: int
    times: np.ndarray
    X_OE: np.ndarray
    X_OE_commanded: np.ndarray
    object_state: np.ndarray
    contact_force: np.ndarray
    X_WO: np.ndarray
    dmp: Dmp
    demo_times: np.ndarray
    failed: bool = False
    reason: str = ""
    message: str = ""
    success: bool = False
    final_object_state: float = math.nan
    wall_s: float = 0.0

    @property
    def reflex_trips(self) -> int:
        """1 when the collision reflex stopped this run, else 0."""
        return int(self.failed and self.reason == "reflex")

    def X_OE_at(self, times) -> np.ndarray:
        """The measured hand pose in O at ``times`` (s), (T, 7).

        Linear in position, normalised linear in the quaternion (signs made
        continuous first), the first and last samples held outside the
        record (a run that stopped early holds where it stopped).
        """
        t = np.asarray(times, dtype=float)
        if len(self.times) == 0:
            raise ValueError(f"imitation of {self.demo}: no samples recorded ({self.reason}: {self.message})")
        out = np.empty((t.size, 7))
        for j in range(7):
            out[:, j] = np.interp(t, self.times, self.X_OE[:, j])
        q = out[:, 3:]
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        return out

    @property
    def X_OE_demo_grid(self) -> np.ndarray:
        """(T, 7) the measured hand path on the demonstration's own ``times_100hz``.

        What a refinement at fit time refits against: demonstration +
        (demonstration - this). On the shared 100 Hz grid the samples are the
        recorded ones (no interpolation) wherever the run lasted.
        """
        return self.X_OE_at(self.demo_times)

    def summary(self) -> dict:
        """JSON-able scalars (no arrays)."""
        return {"demo": self.demo, "seed": int(self.seed), "failed": bool(self.failed), "reason": self.reason,
                "message": self.message, "success": bool(self.success),
                "final_object_state": None if not math.isfinite(self.final_object_state)
                else float(self.final_object_state), "samples": int(len(self.times)),
                "wall_s": round(float(self.wall_s), 3)}


def _demo_name(demo) -> str:
    path = getattr(demo, "path", None)
    if path:
        from pathlib import Path
        return Path(path).name
    return f"seed {int(demo.seed)}"


def _model_parts(model):
    """(name, DmpConfig, station config) of a Skill or an ActionModel."""
    from drake_skill.learning.rollout import ActionModel

    if isinstance(model, ActionModel):
        return model.name, model.dmp_config, None
    return model.name, model.config.dmp, model


class Imitator:
    """Executes DMPs of one skill on demonstrations' object poses; one diagram, built once.

    Args:
        model: a fitted :class:`~drake_skill.fitted_skill.Skill` or an
            :class:`~drake_skill.learning.rollout.ActionModel` (its DMP
            hyper-parameters and finger opening are used; every DMP given to
            :meth:`imitate` must have its number of bases).
        station_config: the scenario (default: the skill's, with the camera
            off; an ActionModel needs one unless ``runner`` is given).
        runner: a built ``RolloutRunner`` with ``object_pose="ground_truth"``,
            no goal model and ``record_hz`` = 100 to reuse instead.
    """

    def __init__(self, model, station_config=None, runner=None):
        from drake_skill.learning.rollout import RolloutConfig, RolloutRunner

        self.model = model
        self.name, self.dmp_config, skill = _model_parts(model)
        if runner is None:
            if station_config is None:
                if skill is None:
                    raise ValueError("station_config: an ActionModel carries no scenario; pass the station "
                                     "config (e.g. load_skill(name).station_config())")
                station_config = skill.station_config()
                station_config.enable_camera = False   # ground-truth frame, no goal model: no camera needed
            else:
                station_config = copy.deepcopy(station_config)
            runner = RolloutRunner(model, station_config, RolloutConfig(
                object_pose="ground_truth", goal_model=False, record_hz=RECORD_HZ))
        config = runner.rollout_config
        if config.object_pose != "ground_truth" or config.goal_model or config.record_hz != RECORD_HZ:
            raise ValueError(f"runner: expected RolloutConfig(object_pose='ground_truth', goal_model=False, "
                             f"record_hz={RECORD_HZ:g}), got {config}")
        self.runner = runner

    @property
    def station(self):
        return self.runner.station

    def _object_pose(self, demo):
        """The demonstration's X_WO_true as a RigidTransform, and whether its seed draws it."""
        from drake_skill.station.recording import pose_to_vector, vector_to_pose

        X_demo = np.asarray(demo.X_WO_true, dtype=float)
        drawn = pose_to_vector(self.station.random_object_pose(int(demo.seed)))
        same = (np.abs(drawn[:3] - X_demo[:3]).max() <= _POSE_MATCH_M
                and 1.0 - abs(float(np.dot(drawn[3:], X_demo[3:]))) <= _POSE_MATCH_Q)
        return vector_to_pose(X_demo), same

    @contextlib.contextmanager
    def _placed(self, X_WO, drawn: bool):
        """Within: the station's reset places the object at ``X_WO`` (when its seed draws another pose:
        another scenario's draw, or the robot)."""
        station = self.station
        if not drawn:
            station.random_object_pose = lambda _seed: X_WO
        try:
            yield
        finally:
            if not drawn:
                del station.random_object_pose

    def _start(self, weights, seed: int, goal, y0_demo, tau: float | None = None) -> np.ndarray:
        """Resets the runner (object pose from ``seed``) and starts its DMP at the measured hand pose in O
        toward ``goal`` (over ``tau`` s, when given); returns that start."""
        runner = self.runner
        runner.reset(weights, seed)
        dmp_context = runner.dmp_system.GetMyMutableContextFromRoot(runner.context)
        y0 = runner.dmp_system.get_dmp(dmp_context).y0.copy()   # measured hand pose in O at reset
        if np.dot(y0[3:], goal[3:]) < 0:
            y0[3:] *= -1
        runner.dmp_system.set_start_goal(dmp_context, y0, goal, y0_demo=y0 if y0_demo is None else y0_demo)
        if tau is not None:
            runner.dmp_system.set_duration(dmp_context, tau)
        return y0

    def move_to_start(self, demo, speed: float = 0.1, min_duration: float = 2.0, within: float = 0.002) -> float:
        """Moves the hand to ``demo``'s first pose in O and stops there; returns the distance [m].

        On the robot a run starts wherever the previous one left the arm;
        a refinement compares each run with the demonstration, so it first
        brings the hand to the demonstration's start. The move is the DMP
        with zero forcing term (the critically damped spring of thesis Eq.
        3.3, at rest at both ends, within 0.1 % of the goal at tau) over
        tau = max(``min_duration``, distance / ``speed``) s, then 0.5 s
        still; a hand already ``within`` m of it does not move. Raises what
        the station raises (the reflex, a stale status).
        """
        from drake_skill.station.recording import advance_station

        runner = self.runner
        goal = np.asarray(demo.X_OE_100hz[0], dtype=float)
        X_WO, drawn = self._object_pose(demo)
        with self._placed(X_WO, drawn):
            y0 = self._start(np.zeros(runner.weights_shape), int(demo.seed), goal, None)
        distance = float(np.linalg.norm(goal[:3] - y0[:3]))
        if distance <= within:
            return distance
        tau = max(float(min_duration), distance / float(speed))
        runner.dmp_system.set_duration(runner.dmp_system.GetMyMutableContextFromRoot(runner.context), tau)
        advance_station(runner.simulator, self.station, runner.context, tau + 0.5)
        return distance

    def imitate(self, dmp: Dmp, demo) -> Imitation:
        """Runs ``dmp`` (weights, goal, tau) on ``demo``'s object pose; returns an :class:`Imitation`.

        ``demo``: a :class:`~drake_skill.demos.format.Demonstration` (read:
        ``seed``, ``X_WO_true``, ``times_100hz``; ``path`` names it). Never
        raises for what the simulation does (the run is marked failed);
        raises ValueError for a DMP of another number of bases.
        """
        from drake_skill.common import IkWarningCounter
        from drake_skill.learning.rollout import classify_failure
        from drake_skill.station.recording import advance_station, pose_to_vector
        from drake_skill.station.success import judge_run

        runner = self.runner
        if dmp.weights.shape != runner.weights_shape:
            raise ValueError(f"dmp: weights of shape {dmp.weights.shape}; this imitator's skill has "
                             f"{runner.weights_shape} (B, d)")
        seed = int(demo.seed)
        X_WO, drawn = self._object_pose(demo)
        station = runner.station
        start = time.perf_counter()
        counter = IkWarningCounter()
        import logging
        logger = logging.getLogger("drake")
        logger.filters.insert(0, counter)
        failure = None
        n = 0
        executed = dmp
        try:
            with self._placed(X_WO, drawn):
                y0 = self._start(dmp.weights, seed, dmp.goal, dmp.demonstrated_start, dmp.tau)
            executed = dmp.with_start(y0)
            n = int(math.ceil((dmp.tau + runner.settle_time) * RECORD_HZ - 1e-9))
            advance_station(runner.simulator, station, runner.context, n / RECORD_HZ)
        except Exception as error:   # kept up to where it stopped
            failure = error
        finally:
            logger.removeFilter(counter)
        records = runner.loggers.read(runner.context, n)
        try:
            records.check_joint_states()
        except Exception as error:
            failure = failure or error
        X_WO_vec = pose_to_vector(X_WO)
        X_OE = (object_frame_poses(X_WO_vec, records.ee_pose) if len(records.times)
                else np.zeros((0, 7)))
        times = np.asarray(records.times, dtype=float)
        commanded = (integrate(executed, self.dmp_config, np.minimum(times, executed.tau)) if len(times)
                     else np.zeros((0, 7)))
        objs = np.asarray(records.object_state, dtype=float)
        success = False
        if failure is None and len(times):
            success = bool(judge_run(times, objs, records.contact_force, runner.config.success))
        return Imitation(
            skill=self.name, demo=_demo_name(demo), seed=seed, times=times, X_OE=X_OE,
            X_OE_commanded=commanded, object_state=objs,
            contact_force=np.asarray(records.contact_force, dtype=float), X_WO=X_WO_vec, dmp=executed,
            demo_times=np.asarray(demo.times_100hz, dtype=float), failed=failure is not None,
            reason="" if failure is None else classify_failure(failure),
            message="" if failure is None else f"{type(failure).__name__}: {failure}"[:500],
            success=success, final_object_state=float(objs[-1]) if len(objs) else math.nan,
            wall_s=time.perf_counter() - start)


def imitate(action_model_or_skill, dmp: Dmp, demo, station_config=None, *, imitator: Imitator | None = None,
            runner=None) -> Imitation:
    """Executes ``dmp`` in the simulated station on ``demo``'s own object pose (module docstring).

    ``action_model_or_skill``: a fitted Skill or an ActionModel;
    ``station_config``: the scenario (default the skill's, camera off).
    Building a station is slow: pass ``imitator`` (an :class:`Imitator` of
    the same model) or a suitable ``runner`` to reuse one across
    demonstrations. Returns an :class:`Imitation` (100 Hz records).
    """
    if imitator is None:
        imitator = Imitator(action_model_or_skill, station_config, runner=runner)
    return imitator.imitate(dmp, demo)


def imitation_metrics(config: DmpConfig, dmp: Dmp, demo, imitation: Imitation | None = None,
                      shift_m: float = 0.05) -> dict:
    """Every figure of ``drake-skill bench imitation`` for one demonstration (plain numpy).

    ``config``: the skill's DmpConfig (scaled columns filled by the fit);
    ``dmp``: the DMP fitted to ``demo``; ``imitation``: its execution
    (:func:`imitate`), or None for the figures that need no simulation
    (fit error and contact shift; the others are then None).

    Keys (lengths in mm, times in ms; see :mod:`drake_skill.action.metrics`):
    ``fit_max_mm``, ``fit_rms_mm``, ``tracking_max_mm``, ``tracking_rms_mm``,
    ``total_max_mm``, ``total_rms_mm``, ``contact_max_mm``, ``lag_ms``,
    ``object_state_demo``, ``object_state_imitation``, ``object_state_error``
    (the object's joint at the end, rad or m, and |difference|),
    ``reflex_trips`` (0 or 1), ``contact_shift_mm`` (start moved by
    ``shift_m`` along x and y of O), ``contact_samples`` (size of the
    near-contact mask), ``failed``, ``reason``, ``success``.
    """
    t = np.asarray(demo.times_100hz, dtype=float)
    X_demo = np.asarray(demo.X_OE_100hz, dtype=float)
    mask = metrics.contact_mask(t, demo.object_state_100hz)
    fit_max, fit_rms = metrics.fit_error(dmp, config, t, X_demo)
    out = {"fit_max_mm": fit_max, "fit_rms_mm": fit_rms,
           "tracking_max_mm": None, "tracking_rms_mm": None,
           "total_max_mm": None, "total_rms_mm": None, "contact_max_mm": None, "lag_ms": None,
           "object_state_demo": float(demo.final_object_state), "object_state_imitation": None,
           "object_state_error": None, "reflex_trips": None,
           "contact_shift_mm": metrics.contact_shift_mm(dmp, config, t, mask, shift_m),
           "contact_samples": int(mask.sum()), "failed": None, "reason": None, "success": None}
    if imitation is not None and len(imitation.times):
        track_max, track_rms = metrics.tracking_error(imitation.X_OE, imitation.X_OE_commanded)
        dt = float(np.median(np.diff(t)))
        out.update(metrics.total_error(imitation.X_OE, X_demo, mask))
        out.update(tracking_max_mm=track_max, tracking_rms_mm=track_rms,
                   lag_ms=metrics.lag_ms(imitation.X_OE, X_demo, dt),
                   object_state_imitation=imitation.final_object_state,
                   object_state_error=abs(imitation.final_object_state - float(demo.final_object_state)))
    if imitation is not None:
        out.update(reflex_trips=imitation.reflex_trips, failed=bool(imitation.failed), reason=imitation.reason,
                   success=bool(imitation.success))
    return out


def check_demo_pairs(skill, demos, where: str) -> None:
    """Raises ValueError unless ``demos`` are the ones ``skill`` was fitted from (same count, each DMP's start
    within 1 mm of its demonstration's); ``where`` names the folder in the message."""
    if len(skill.dmps) != len(demos):
        raise ValueError(f"{where}: {len(demos)} demonstrations, but the skill was fitted from {len(skill.dmps)}; "
                         "give the folder it was fitted from as --demos")
    for i, (dmp, demo) in enumerate(zip(skill.dmps, demos)):
        gap = float(np.linalg.norm(dmp.y0[:3] - demo.X_OE[0, :3]))
        if gap > 1e-3:
            raise ValueError(f"{where}: {Path(demo.path or f'demo {i}').name} starts {1e3 * gap:.1f} mm from the "
                             f"skill's DMP {i}; give the folder the skill was fitted from as --demos")
