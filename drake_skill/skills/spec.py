"""The skill file: its schema, its loader and its checks (docs/skills.md).

(No ``from __future__ import annotations`` here: yaml_load_typed reads the
field types at run time.)
"""

import dataclasses as dc
import math
import typing
from pathlib import Path

import numpy as np
from pydrake.common.schema import Transform
from pydrake.math import RigidTransform, RotationMatrix

from drake_skill import typed_yaml
from drake_skill.reward.pomrp import REWARDS
from drake_skill.typed_yaml import load_typed
from drake_skill.station.scenario import (SCENARIO_DIR, Scenario, SuccessConfig, load_scenario,
                                        object_joint_name, validate_success)
from drake_skill.station.limits import FINGER_MAX

__all__ = ["Keyframe", "SkillSpec", "keyframes", "load_skill", "shipped_skill_names", "shipped_skills"]

SKILL_DIR = Path(__file__).resolve().parent

#: How a skill picks the DMP policy search starts from (SkillSpec.initial_dmp).
INITIAL_DMP_RULES = ("random", "best-return")

#: The Panda's reach: the hand's TCP at most this far from the shoulder (joint 2's axis,
#: 0.333 m above the base) [m]: Franka's datasheet gives 855 mm to the flange.
SHOULDER = np.array([0.0, 0.0, 0.333])
REACH_M = 0.855


@dc.dataclass
class Keyframe:
    """One via point of the scripted demonstrator's motion, in the object frame O.

    t: time after the start (the hand leaves its home pose at 0) [s].
    gripper: finger opening (distance between the fingers) [m].
    pose: X_OE, the hand's TCP frame E in O (translation [m], rotation:
      Drake's schema, e.g. ``!Rpy {deg: [r, p, y]}``).
    least: X_OE at follow-through 0 (the least motion that still succeeds;
      ``DemonstratorConfig.follow_through_range``): a demonstration with
      follow-through f takes the pose at f of the screw motion from ``least``
      to ``pose`` (a hand turning with a lid stays on the hinge's arc). None:
      the pose does not depend on how far the hand carries the object.
    """

    t: float = 0.0
    gripper: float = 0.0
    pose: Transform = dc.field(default_factory=Transform)
    least: typing.Optional[Transform] = None


@dc.dataclass
class SkillSpec:
    """What makes a skill beyond its demonstrations (a skill file; docs/skills.md).

    name: the skill's name (letters, digits, ``_`` and ``-``).
    description: one sentence for ``drake-skill skills``.
    scenario: a shipped scenario's name (``drake_skill/station/scenarios/``)
      or a path to a scenario YAML, relative to the skill file.
    demonstrations: how many the scripted demonstrator records (thesis 6.2: 2-3).
    dmp_bases: basis functions per DMP dimension, an override: None (the
      default) lets ``drake-skill fit`` choose the fewest that meet the fit
      tolerance (docs/method.md section 2.2); a number fixes B (thesis
      Table 6.1: 20 Open, 10 Close, 9 Draw).
    exploration_scale: sigma_0 of thesis Eq. 5.3, a factor on Sigma_b^0
      (docs/method.md section 5).
    dmp_unscaled_dims: DMP weight columns (0-2: x, y, z of the object frame;
      3-6: the quaternion w, x, y, z) never scaled by g - y0, whatever the
      demonstrations move along them (``DmpConfig.unscaled_dims``,
      docs/method.md section 2); empty: the automatic choice alone.
    initial_dmp: which demonstration's DMP policy search starts from:
      "random" (thesis 5.2: drawn by the fit's seed) or "best-return" (the
      one whose plain imitation earns the highest mean learned return on
      ``initial_dmp_poses`` object poses; docs/method.md section 5).
    initial_dmp_poses: object poses per DMP for "best-return".
    gripper_opening: the finger opening [m] the skill holds while it runs;
      None: the median of the demonstrations' (docs/method.md section 2).
    reward: the learned reward: "progress" (default; how far the object moved along
      the change the demonstrations showed, docs/method.md section 4.4) or "states"
      (thesis Eq. 4.4, the MRP values of the goal HMM's states; the thesis skills').
    success: the ground-truth rule on the object's joint (simulation only).
    keyframes: the scripted demonstrator's motion; empty: demonstrations
      come from Meshcat teleoperation or the robot.
    """

    name: str = ""
    description: str = ""
    scenario: str = ""
    demonstrations: int = 3
    dmp_bases: typing.Optional[int] = None
    exploration_scale: float = 1.0
    dmp_unscaled_dims: typing.List[int] = dc.field(default_factory=list)
    initial_dmp: str = "random"
    initial_dmp_poses: int = 3
    gripper_opening: typing.Optional[float] = None
    reward: str = "progress"
    success: SuccessConfig = dc.field(default_factory=SuccessConfig)
    keyframes: typing.List[Keyframe] = dc.field(default_factory=list)

    # ------------------------------------------------------------------ the scenario
    def scenario_path(self) -> Path:
        """The scenario file: a shipped scenario by name, else the path as given (made absolute on load)."""
        if self.scenario and "/" not in self.scenario and not self.scenario.endswith((".yaml", ".yml")):
            return SCENARIO_DIR / f"{self.scenario}.yaml"
        return Path(self.scenario)

    def station_config(self) -> Scenario:
        """The skill's scenario with the skill's success rule (a fresh object each call)."""
        config = load_scenario(self.scenario_path())
        config.success = dc.replace(self.success)
        return config

    def station_defaults(self, overrides=None) -> Scenario:
        """The scenario a command runs: the skill's, or ``overrides`` (a path) loaded over it."""
        if overrides is None:
            return self.station_config()
        config = load_scenario(overrides, defaults=self.station_config())
        return config


def _bad(where: str, field: str, value, expected: str):
    """The one error format of drake-skill's configurations (``drake_skill.typed_yaml.bad``)."""
    typed_yaml.bad(f"skill file {where}", field, value, expected)


def _check(spec: SkillSpec, where: str) -> SkillSpec:
    """Raises a one-line ValueError naming the file, the field and the fix."""
    if not spec.name or not all(c.isalnum() or c in "_-" for c in spec.name):
        _bad(where, "name", spec.name, "a name of letters, digits, '_' and '-'")
    if not spec.scenario:
        _bad(where, "scenario", spec.scenario, "a shipped scenario's name (drake-skill skills) or a scenario YAML")
    path = spec.scenario_path()
    if not path.is_file():
        shipped = ", ".join(sorted(p.stem for p in SCENARIO_DIR.glob("*.yaml")))
        _bad(where, "scenario", spec.scenario,
             f"a shipped scenario ({shipped}) or an existing YAML file ({path} does not exist)")
    if int(spec.demonstrations) < 1:
        _bad(where, "demonstrations", spec.demonstrations, "at least 1 (the thesis: 2 or 3)")
    if spec.dmp_bases is not None and not 3 <= int(spec.dmp_bases) <= 100:
        _bad(where, "dmp_bases", spec.dmp_bases, "3..100 basis functions (thesis Table 6.1: 9-20), or null to "
             "choose them from the fit tolerance")
    if not (math.isfinite(spec.exploration_scale) and 0 < spec.exploration_scale <= 100):
        _bad(where, "exploration_scale", spec.exploration_scale, "a factor in (0, 100] on Sigma_b^0")
    dims = list(spec.dmp_unscaled_dims)
    if any(not 0 <= int(i) <= 6 for i in dims) or len(set(dims)) != len(dims):
        _bad(where, "dmp_unscaled_dims", dims, "distinct weight columns in 0..6 (0-2: x, y, z; 3-6: quaternion w, x, "
             "y, z)")
    if spec.initial_dmp not in INITIAL_DMP_RULES:
        _bad(where, "initial_dmp", spec.initial_dmp, f"one of {', '.join(INITIAL_DMP_RULES)}")
    if not 1 <= int(spec.initial_dmp_poses) <= 100:
        _bad(where, "initial_dmp_poses", spec.initial_dmp_poses, "1..100 object poses per demonstration's DMP")
    if spec.gripper_opening is not None and not 0.0 <= spec.gripper_opening <= 2 * FINGER_MAX:
        _bad(where, "gripper_opening", spec.gripper_opening,
             f"an opening in [0, {2 * FINGER_MAX}] m, or null for the demonstrations' median")
    if spec.reward not in REWARDS:
        _bad(where, "reward", spec.reward, f"one of {', '.join(REWARDS)} (docs/method.md section 4.4)")
    validate_success(spec.success, "success", what=f"skill file {where}")
    t_prev = 0.0
    for i, k in enumerate(spec.keyframes):
        if not (math.isfinite(k.t) and k.t > t_prev):
            _bad(where, f"keyframes[{i}].t", k.t, f"times that increase from 0 (the previous is {t_prev} s)")
        t_prev = k.t
        if not 0.0 <= k.gripper <= 2 * FINGER_MAX:
            _bad(where, f"keyframes[{i}].gripper", k.gripper, f"an opening in [0, {2 * FINGER_MAX}] m")
    return spec


def check_with_scenario(spec: SkillSpec, config: Scenario, where: str = "") -> None:
    """Checks what needs the scenario too: the success rule's joint is the object's,
    and every keyframe is within the arm's reach on every object pose the scenario draws."""
    where = where or f"skill {spec.name!r}"
    joint = object_joint_name(config)
    if spec.success.joint != joint:
        _bad(where, "success.joint", spec.success.joint,
             f"the scenario's object's one joint, '{joint}'")
    obj = config.object
    for i, (_, p_OE, _, _) in enumerate(keyframes(spec)):
        for sx in (-1, 1):
            for sy in (-1, 1):
                for syaw in (-1, 1):
                    X_WO = RigidTransform(RotationMatrix.MakeZRotation(obj.yaw + syaw * obj.randomize_yaw),
                                          [obj.x + sx * obj.randomize_xy, obj.y + sy * obj.randomize_xy, 0.0])
                    far = float(np.linalg.norm(X_WO @ p_OE - SHOULDER))
                    if far > REACH_M:
                        _bad(where, f"keyframes[{i}].pose", [round(float(v), 3) for v in p_OE],
                             f"a pose within the Panda's {REACH_M} m reach on every object pose the "
                             f"scenario draws (this one is {far:.2f} m from the shoulder); move it or the "
                             "object closer")


def _screw(X0: RigidTransform, X1: RigidTransform, f: float) -> RigidTransform:
    """The pose at fraction f of the constant-twist (screw) motion from X0 to X1:
    X(f) = exp(f log(X1 X0^-1)) X0 (SE(3), scipy's matrix exp and log). A hand
    that turns with a lid about its hinge stays on the hinge's arc, as a
    straight-line blend of positions would not."""
    from scipy.linalg import expm, logm

    if f <= 0.0:
        return X0
    twist = np.real(logm((X1 @ X0.inverse()).GetAsMatrix4()))
    M = expm(f * twist) @ X0.GetAsMatrix4()
    return RigidTransform(RotationMatrix.ProjectToRotationMatrix(M[:3, :3]), M[:3, 3])


def keyframes(spec: SkillSpec, follow_through: float = 1.0) -> list:
    """The keyframes as (t [s], p_OE [m], R_OE, opening [m]) at ``follow_through`` in [0, 1]."""
    if not 0.0 <= follow_through <= 1.0:
        raise ValueError(f"follow_through: expected a fraction in [0, 1], got {follow_through!r}")
    frames = []
    for k in spec.keyframes:
        X = k.pose.GetDeterministicValue()
        if k.least is not None and follow_through < 1.0:
            X = _screw(k.least.GetDeterministicValue(), X, follow_through)
        frames.append((float(k.t), X.translation(), X.rotation(), float(k.gripper)))
    return frames


def shipped_skill_names() -> list[str]:
    """The skills shipped with the library (files in ``drake_skill/skills/``), by name."""
    return sorted(p.stem for p in SKILL_DIR.glob("*.yaml"))


def shipped_skills() -> list[SkillSpec]:
    return [load_skill(name) for name in shipped_skill_names()]


def _looks_like_path(text: str) -> bool:
    return "/" in text or text.endswith((".yaml", ".yml"))


def load_skill(skill) -> SkillSpec:
    """A skill from a shipped skill's name or a path to a skill file (a SkillSpec passes through).

    Raises ValueError (one line: the file, the field, the fix) for a file that
    cannot work, FileNotFoundError for a name that is neither.
    """
    if isinstance(skill, SkillSpec):
        return skill
    text = str(skill)
    path = Path(text) if _looks_like_path(text) else SKILL_DIR / f"{text}.yaml"
    if not path.is_file():
        if _looks_like_path(text):
            raise FileNotFoundError(f"skill file {text}: no such file; give a shipped skill's name "
                                    f"({', '.join(shipped_skill_names())}) or an existing skill YAML")
        raise FileNotFoundError(f"skill {text!r}: not a shipped skill ({', '.join(shipped_skill_names())}) "
                                "and not a file; give one of those or a path to a skill YAML")
    where = str(path)
    try:
        spec = load_typed(SkillSpec, what="skill file", path=path)
    except ValueError as e:
        raise ValueError(f"{e}; see docs/skills.md for the fields") from None
    if spec.scenario and _looks_like_path(spec.scenario) and not Path(spec.scenario).is_absolute():
        spec.scenario = str((path.parent / spec.scenario).resolve())
    _check(spec, where)
    try:
        check_with_scenario(spec, spec.station_config(), where)
    except ValueError as e:
        if str(e).startswith((where, f"skill file {where}")):      # the skill file's own field
            raise
        raise ValueError(f"{where}: scenario {spec.scenario}: {e}") from None
    return spec


def scenario_for_skill(skill) -> Scenario:
    """The scenario of a skill (a shipped skill's name, a skill file's path or a
    :class:`SkillSpec`) with the skill's success rule."""
    return load_skill(skill).station_config()
