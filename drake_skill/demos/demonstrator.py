"""Scripted demonstrator: a skill's keyframes shown in the simulated station, as a person would.

The simulation's stand-in for the thesis' kinesthetic demonstrations (section
6.2: 3 Open, 2 Close, 2 Draw). A skill file's keyframes (``drake_skill.skills``, in
the object frame O) are interpolated with human-like, seeded variation and
played into the station; the demonstration records what a kinesthetic
recording would:

* action data (thesis 6.3): the *measured* hand pose X_WE at 100 Hz,
  expressed in the object frame, X_OE = X_WO^-1 X_WE. X_WO is the object's
  *ground-truth* pose at the start of the demonstration (the simulator knows
  it; the base is locked, so it does not change). In free space the hand
  follows its command within a few millimetres; in contact the command
  lies inside the object (the joint impedance turns that offset into the
  pushing force) while the measured hand stays where the object stops it,
  centimetres away. The record keeps the measured path only, so replaying
  it as a command pushes less than the demonstration did: our analogue of
  kinesthetic teaching changing the dynamics, one of the two reasons the
  thesis gives for the initial imitation being imperfect (the other,
  non-expert demonstrations, is the variation below). The 10 Hz action
  data are the 100 Hz samples taken uniformly (every 10th, last kept).
* perceptual data: the camera's cloud at 10 Hz (the camera frames are the
  10 Hz action instants), segmented by the ``ObjectSegmenter`` system wired in
  the diagram, the very system skill executions use (the same 2048 points, and
  an invalid frame holds the last valid one), a validity flag, and the
  perceived X_WO at the first valid frame. The full 640 x 480 clouds are not kept: 100 frames of
  307,200 points are ~370 MB per demonstration. Per frame, how many pixels were
  of the object's hue, object-coloured and kept by the segment, the peak contact force, and three
  small pictures with the segment (start, first contact, end; schema 2,
  ``drake_skill.demos.format``).

Human-like variation (``DemonstratorConfig``, all drawn from the seed):
per-segment timing scale and via-point position noise (``scripted_plan``), a
constant grasp offset for the whole demonstration (a person puts the hand in
a slightly different place each time), small orientation noise, a
hesitation pause at a random keyframe, and an overshoot of the approach.

A variation can fail (the finger misses the lid lip); the demonstrator then
tries the next seed, so the recorded ``seed`` is the one that succeeded, and
``metadata["rejected_seeds"]`` lists the ones that did not.

    demos = ScriptedDemonstrator("open", DemonstratorConfig(count=3)).record_many()
"""

import dataclasses as dc
import functools
import math
from typing import Callable

import numpy as np
from pydrake.common.eigen_geometry import AngleAxis
from pydrake.math import RigidTransform, RotationMatrix

from drake_skill import typed_yaml
from drake_skill.typed_yaml import load_typed
from drake_skill.demos.format import Demonstration, downsample_action, object_frame_poses, snapshot_frames
from drake_skill.demos.force_margin import peaks
from drake_skill.station.pose_source import PosePlan
from drake_skill.station.loggers import FrameRecords, StationRecords, frame_peaks
from drake_skill.station.recording import ReflexError, pose_to_vector
from drake_skill.station.sim.simulation import StationSimulation
from drake_skill.station.success import judge_run
from drake_skill.skills import SkillSpec, keyframes, load_skill
from drake_skill.station.scenario import Scenario


@dc.dataclass
class DemonstratorConfig:
    """How the scripted demonstrator varies and records its demonstrations.

    count: demonstrations to record; 0 means the skill file's ``demonstrations``
      (the thesis's: 3 Open, 2 Close, 2 Draw).
    seed: the first seed tried. Demonstration i uses the i-th seed (from
      ``seed`` upward) whose variation succeeds; the seed also draws the
      object's pose on the table.
    time_scale_range: each keyframe segment's duration is scaled by a factor
      uniform in [1 - r, 1 + r].
    path_noise: standard deviation of the Gaussian noise on every via point [m].
    grasp_offset: standard deviation of one constant offset added to every
      keyframe of a demonstration, per axis of O [m].
    orientation_noise_deg: standard deviation of a random rotation (about a
      random axis) of each via point's hand orientation [deg].
    pause_probability: probability of a hesitation at one random keyframe
      (default 0: timing differences between demonstrations go into Sigma_0,
      docs/method.md section 6).
    pause_range: its duration, uniform in [min, max] [s].
    overshoot: the approach (first move from home) goes this far past its
      target before settling back [m]; scaled by a uniform factor in [0.5, 1].
    follow_through_range: how far the motion carries the object, a fraction
      drawn uniform in [min, max] per demonstration
      (a skill file's keyframes and their ``least`` poses: 0 the least that
      still succeeds, 1 the scripted motion), as a person stops pushing once
      the object looks done.
    max_force_fraction: a demonstration whose peak robot-scene contact force
      exceeds this fraction of the collision reflex's limit
      (``Scenario.reflex.contact_force_max``) is rejected like a failed
      one, as a person who feels the hand press on the object starts again
      (1: keep every successful one). One accepted above
      ``drake_skill.demos.force_margin.FORCE_MARGIN`` (60 %) of the limit is
      named by a warning when ``drake-skill demos record`` saves it.
    settle_time: the last keyframe is held this long before the recording ends [s]
      (at least the scenario's ``success.settle_time``, the judge's settle phase).
    max_attempts: seeds tried per demonstration before giving up.
    record_hz: rate of the raw action data [Hz] (the thesis: 100).
    action_hz: rate of the downsampled action data [Hz] (the thesis: 10);
      record_hz must be an integer multiple of it, and the camera runs at it.
    record_perception: render and segment the camera at action_hz (off:
      faster, no perception fields; the station is built without a camera).

    How much this variation leaves plain DMP imitation to learn is measured by
    ``tools/imitation_success.py --all-demos`` (figures in the issue notes,
    not here: they change with the station's physics).
    """

    count: int = 0
    seed: int = 0
    time_scale_range: float = 0.05
    path_noise: float = 0.003
    grasp_offset: float = 0.004
    orientation_noise_deg: float = 2.0
    pause_probability: float = 0.0
    pause_range: list[float] = dc.field(default_factory=lambda: [0.2, 0.8])
    overshoot: float = 0.02
    follow_through_range: list[float] = dc.field(default_factory=lambda: [0.2, 1.0])
    max_force_fraction: float = 0.8
    settle_time: float = 0.5
    max_attempts: int = 10
    record_hz: float = 100.0
    action_hz: float = 10.0
    record_perception: bool = True

    def validate(self) -> "DemonstratorConfig":
        """Raises ValueError naming the field that cannot work; returns self."""
        bad = functools.partial(typed_yaml.bad, "demonstrator config")

        if self.count < 0:
            bad("count", self.count, "0 (thesis default) or a positive number of demonstrations")
        if not 0.0 <= self.time_scale_range < 1.0:
            bad("time_scale_range", self.time_scale_range, "a fraction in [0, 1)")
        for name in ("path_noise", "grasp_offset", "orientation_noise_deg", "overshoot", "settle_time"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                bad(name, value, "a finite value >= 0")
        if not 0.0 <= self.pause_probability <= 1.0:
            bad("pause_probability", self.pause_probability, "a probability in [0, 1]")
        if len(self.pause_range) != 2 or not 0 <= self.pause_range[0] <= self.pause_range[1]:
            bad("pause_range", self.pause_range, "[min, max] with 0 <= min <= max [s]")
        r = self.follow_through_range
        if len(r) != 2 or not 0.0 <= r[0] <= r[1] <= 1.0:
            bad("follow_through_range", r, "[min, max] with 0 <= min <= max <= 1")
        if not (math.isfinite(self.max_force_fraction) and 0.0 < self.max_force_fraction <= 1.0):
            bad("max_force_fraction", self.max_force_fraction, "a fraction in (0, 1]")
        if self.max_attempts < 1:
            bad("max_attempts", self.max_attempts, "at least 1")
        if not (self.action_hz > 0 and self.record_hz >= self.action_hz):
            bad("record_hz/action_hz", (self.record_hz, self.action_hz), "0 < action_hz <= record_hz")
        ratio = self.record_hz / self.action_hz
        if abs(ratio - round(ratio)) > 1e-9:
            bad("record_hz/action_hz", (self.record_hz, self.action_hz),
                "record_hz an integer multiple of action_hz")
        return self

    def count_for(self, spec: SkillSpec) -> int:
        return self.count if self.count > 0 else int(spec.demonstrations)


class DemonstratorError(ValueError):
    """The scripted demonstrator could not show the skill within its attempts: the message says
    which settings to change (a user error: ``drake-skill`` prints it as one line, exit 2)."""


def load_demonstrator_config(path=None, *, data: str | None = None) -> DemonstratorConfig:
    """A DemonstratorConfig from a YAML file or string (missing keys keep their defaults)."""
    return load_typed(DemonstratorConfig, what="demonstrator config", path=path, data=data).validate()


# --------------------------------------------------------------------------- variation
def humanlike_plan(skill, X_WO: RigidTransform, X_WE_home: RigidTransform, seed: int,
                   config: DemonstratorConfig) -> tuple[PosePlan, dict]:
    """The keyframes of ``skill`` (a name, a skill file or a SkillSpec) with the seeded variation of ``config``.

    Returns the plan (world frame, starts at home at t = 0) and a JSON-able
    description of the variation drawn (for the file's metadata).
    """
    spec = load_skill(skill)
    rng = np.random.default_rng([int(seed), 0x5EED])
    frames = keyframes(spec)
    if not frames:
        raise ValueError(f"skill {spec.name!r} has no keyframes to script; record its demonstrations by "
                         "teleoperation (drake-skill demos record --interactive) or on the robot")
    offset = rng.normal(0.0, config.grasp_offset, size=3)
    # Per keyframe: duration scale, position noise, orientation noise.
    n = len(frames)
    scales = rng.uniform(1 - config.time_scale_range, 1 + config.time_scale_range, size=n)
    noise = rng.normal(0.0, config.path_noise, size=(n, 3))
    axes = rng.normal(size=(n, 3))
    angles = np.deg2rad(rng.normal(0.0, config.orientation_noise_deg, size=n))
    pause_at = int(rng.integers(0, n)) if rng.uniform() < config.pause_probability else -1
    pause = float(rng.uniform(*config.pause_range))
    overshoot = config.overshoot * float(rng.uniform(0.5, 1.0))
    follow_through = float(rng.uniform(*config.follow_through_range))   # drawn last: the others keep their values
    frames = keyframes(spec, follow_through)

    times, poses, grip = [0.0], [X_WE_home], [float(frames[0][3])]
    t, t_key_prev = 0.0, 0.0
    for i, (t_key, p_OE, R_OE, opening) in enumerate(frames):
        dt = (t_key - t_key_prev) * scales[i]
        t_key_prev = t_key
        axis = axes[i] / np.linalg.norm(axes[i])
        R = RotationMatrix(AngleAxis(angles[i], axis)) @ R_OE
        X_WE = X_WO @ RigidTransform(R, p_OE + offset + noise[i])
        if i == 0 and overshoot > 0:
            # Approach overshoot: 80 % of the way in, pass the target, settle back.
            p0, p1 = X_WE_home.translation(), X_WE.translation()
            direction = (p1 - p0) / max(np.linalg.norm(p1 - p0), 1e-9)
            times.append(t + 0.85 * dt)
            poses.append(RigidTransform(X_WE.rotation(), p1 + overshoot * direction))
            grip.append(float(opening))
            dt += 0.3 * dt
        if dt <= 1e-3:          # a keyframe repeated at the same time: a scripted pause of 0 s
            dt = 1e-3
        t += dt
        times.append(t)
        poses.append(X_WE)
        grip.append(float(opening))
        if i == pause_at and pause > 0:
            t += pause
            times.append(t)
            poses.append(X_WE)
            grip.append(float(opening))
    variation = {"grasp_offset_m": offset.tolist(), "time_scales": scales.tolist(),
                 "pause_after_keyframe": pause_at, "pause_s": pause if pause_at >= 0 else 0.0,
                 "overshoot_m": overshoot, "follow_through": follow_through}
    return PosePlan.from_poses(times, poses, grip), variation


# --------------------------------------------------------------------------- recording
def demonstration_from(records: StationRecords, record_hz: float, action_hz: float, skill: str, seed: int,
                       X_WO_true: RigidTransform, success: bool, metadata: dict) -> Demonstration:
    """Assembles a recording's samples (:class:`~drake_skill.station.loggers.StationRecords`
    at ``record_hz``, ending on an action instant; with perception, its camera frames at
    ``action_hz``: the ObjectSegmenter's points, pixel counts and three pictures,
    ``metadata["snapshot_labels"]`` naming them) into a Demonstration (times start at 0).
    Its metadata gets the reflex monitor's peaks and their times [s]:
    ``peak_contact_force_N``, ``peak_contact_force_time_s``, ``peak_external_torque_Nm``
    (7) and ``peak_external_torque_time_s`` (7) (``drake_skill.demos.force_margin``)."""
    n = records.times.size
    k = int(round(record_hz / action_hz))
    if n == 0 or (n - 1) % k:
        raise ValueError(f"a recording of {n} samples at {record_hz:g} Hz does not end on a "
                         f"{action_hz:g} Hz action instant")
    times = np.arange(n) / record_hz
    X_WO = pose_to_vector(X_WO_true)
    X_OE_raw = object_frame_poses(X_WO, records.ee_pose)
    idx, t10, X_OE = downsample_action(times, X_OE_raw, action_hz)
    obj = records.object_state
    peak_force = frame_peaks(records.contact_force, idx)
    perception = {}
    frames = records.frames
    if frames is not None:
        if not np.array_equal(frames.index, idx):
            raise ValueError(f"camera frames at samples {frames.index[:3].tolist()}..., the {action_hz:g} Hz "
                             f"action data at {idx[:3].tolist()}...: the camera must run at action_hz")
        first = frames.first_valid
        if first is None:
            raise ValueError(f"{skill} seed {seed}: the segmentation found the object in none of "
                             f"the {idx.size} camera frames")
        perception = dict(object_points=frames.points, perception_valid=frames.valid, X_WO_start=frames.X_WO[first])
        segment, labels = _segment_fields(frames, peak_force, obj[idx])
        perception.update(segment)
        metadata = dict(metadata, X_WO_start_frame=first, snapshot_labels=labels)
    # The reflex monitor's peaks and their times, for the force margin (drake_skill.demos.force_margin).
    force, t_force = peaks(times, records.contact_force)
    torque, t_torque = peaks(times, records.external_torque)
    metadata = dict(metadata, peak_contact_force_N=float(force[0]), peak_contact_force_time_s=float(t_force[0]),
                    peak_external_torque_Nm=torque.tolist(), peak_external_torque_time_s=t_torque.tolist())
    return Demonstration(
        skill=skill, seed=int(seed), success=bool(success), final_object_state=float(obj[-1]),
        times_100hz=times, X_OE_100hz=X_OE_raw, q_100hz=records.state[:, :7].copy(),
        gripper_100hz=records.gripper.copy(), object_state_100hz=obj,
        times=t10, X_OE=X_OE, X_WO_true=X_WO, peak_force=peak_force, metadata=metadata, **perception)


def _segment_fields(frames: FrameRecords, peak_force: np.ndarray,
                    object_state: np.ndarray) -> tuple[dict[str, np.ndarray], list[str]]:
    """The frames' pixel counts and their start / first contact / end pictures as the
    Demonstration's ``pixels_*`` and ``snapshot_*`` fields, and the pictures' labels."""
    index, labels = snapshot_frames(peak_force, object_state)
    counts = frames.pixel_counts
    shots = [frames.pixels[k] for k in index]
    return dict(pixels_hue=counts[:, 0], pixels_coloured=counts[:, 1], pixels_kept=counts[:, 2], snapshot_index=index,
                snapshot_rgb=np.stack([p.rgb for p in shots]),
                snapshot_segment=np.stack([p.hue.astype(np.uint8) + p.coloured + p.kept for p in shots])), labels


# --------------------------------------------------------------------------- demonstrator
class ScriptedDemonstrator:
    """Records scripted, human-like demonstrations of one skill in one built station.

    skill: a shipped skill's name, a skill file or a SkillSpec; config: the variation and recording
    settings; station_config: the scenario (default ``scenario_for_skill``;
    its camera is switched off when ``config.record_perception`` is false).
    """

    def __init__(self, skill, config: DemonstratorConfig | None = None,
                 station_config: Scenario | None = None, meshcat=None):

        self.spec = load_skill(skill)
        self.skill = self.spec.name
        self.config = (config or DemonstratorConfig()).validate()
        station_config = station_config or self.spec.station_config()
        if not self.config.record_perception:
            station_config.enable_camera = False
        elif not station_config.enable_camera:
            raise ValueError("record_perception needs a station with enable_camera = true")
        self.sim = StationSimulation(station_config, meshcat=meshcat, perceive=self.config.record_perception,
                                     record_hz=self.config.record_hz)

    def record(self, seed: int) -> Demonstration:
        """One demonstration on the object pose and variation drawn from ``seed``.

        Deterministic: the same seed gives the same arrays. ``success`` is the
        ground-truth verdict; it may be False (see :meth:`record_many`).
        """
        sim, config = self.sim, self.config
        X_WO = sim.reset(seed)
        plan, variation = humanlike_plan(self.spec, X_WO, sim.home_pose(), seed, config)
        sim.set_plan(plan)
        duration = plan.duration + max(config.settle_time, sim.config.success.settle_time)
        k = int(round(config.record_hz / config.action_hz))
        records = sim.record(int(math.ceil(duration * config.action_hz - 1e-9)) * k)   # from t = 0, a frame
        success = judge_run(records.times, records.object_state, records.contact_force, sim.config.success)
        metadata = {"source": "scripted", "variation": variation,
                    "demonstrator_config": dc.asdict(config),
                    "X_WO_note": "X_OE uses the ground-truth X_WO_true at the start (simulation)"}
        return demonstration_from(records, config.record_hz, config.action_hz, self.skill, seed, X_WO, success,
                                  metadata)

    def record_many(self, count: int | None = None, progress: bool = True,
                    on_attempt: Callable[[int, Demonstration], None] | None = None) -> list[Demonstration]:
        """``count`` (default: config) successful demonstrations on successive seeds.

        A seed whose variation fails, trips the collision reflex, or presses
        harder than ``max_force_fraction`` of the reflex limit, is skipped (the next seed is tried; at
        most ``max_attempts`` per demonstration, else :class:`DemonstratorError`). Each
        demonstration's ``metadata["rejected_seeds"]`` lists the seeds skipped
        just before it.
        """
        from tqdm import tqdm

        count = self.config.count_for(self.spec) if count is None else int(count)
        force_limit = self.config.max_force_fraction * self.sim.config.reflex.contact_force_max
        demos, seed = [], int(self.config.seed)
        bar = tqdm(total=count, desc=f"{self.skill} demonstrations", unit="demo", disable=not progress)
        try:
            for _ in range(count):
                rejected = []
                for _attempt in range(self.config.max_attempts):
                    try:
                        demo = self.record(seed)
                    except ReflexError as reflex:
                        # The robot stopped itself: the person starts again, as after a failure.
                        demo, why = None, f"reflex at {reflex.time_s:.1f} s ({reflex.force_N:.0f} N)"
                    if demo is not None and on_attempt is not None:
                        on_attempt(seed, demo)
                    seed += 1
                    if demo is not None:
                        force = float(demo.metadata["peak_contact_force_N"])
                        if demo.success and force <= force_limit:
                            break
                        why = (f"failed ({demo.final_object_state:.3f})" if not demo.success
                               else f"pressed {force:.0f} N")
                    rejected.append(seed - 1)
                    bar.set_postfix_str(f"seed {seed - 1} {why}; retrying")
                else:
                    raise DemonstratorError(
                        f"{self.skill}: {self.config.max_attempts} variations in a row failed, tripped the reflex "
                        f"or pressed harder than {force_limit:.0f} N (seeds {rejected[0]}..{rejected[-1]}; the last "
                        f"{why}); reduce the variation (time_scale_range, path_noise, grasp_offset, overshoot) "
                        "or raise max_force_fraction")
                demo.metadata["rejected_seeds"] = rejected
                demos.append(demo)
                bar.set_postfix_str(f"seed {demo.seed}: {demo.final_object_state:.3f}")
                bar.update(1)
        finally:
            bar.close()
        return demos
