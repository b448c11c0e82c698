"""Ground-truth success judges (simulation only; never used as a reward).

docs/method.md section 4: reported success rates in simulation use the
simulator's ground truth. A skill's success rule (its skill file's
``success``, :class:`~drake_skill.station.scenario.SuccessConfig`) reads the
object's joint, which the station's ``object_state`` port gives (a lid's
angle [rad], a drawer's travel [m]): its final value must be at or above
``above`` (Open: past the lid's tipping angle, so that a lid judged open stays
open by its own weight once the hand has left; Draw: the drawer out), or at
or below ``below`` (Close: shut). The verdict reads the state at the end of a
settle phase (``settle_time``) in which the hand holds still away from the
object: a run whose hand still touches the scene then fails, as the object's
state is held by the hand, not by itself.
"""

from __future__ import annotations

import numpy as np

from drake_skill.station.scenario import SuccessConfig

#: Contact force below this counts as "not touching" in the settle phase [N].
TOUCH_FORCE_N = 1e-3


def judge_success(object_state: float, rule: SuccessConfig) -> bool:
    """True if the final ``object_state`` satisfies the rule (above or below its value)."""
    if not rule.joint:
        raise ValueError("success rule: no joint; a run is judged by a skill's rule (its skill file's 'success')")
    value = float(object_state)
    if rule.above is not None:
        return value >= rule.above
    return value <= rule.below


def hand_left(times, contact_force, rule: SuccessConfig) -> bool:
    """True if the robot touched nothing in the last ``settle_time`` s of the run
    (``contact_force``: (T,) peak robot-scene force per sample [N])."""
    times, force = np.asarray(times, dtype=float), np.asarray(contact_force, dtype=float)
    settle = times >= times[-1] - rule.settle_time + 1e-9
    return bool(np.all(force[settle] < TOUCH_FORCE_N))


def judge_run(times, object_state, contact_force, rule: SuccessConfig) -> bool:
    """The verdict of a recorded run: :func:`judge_success` on the last object
    state, and :func:`hand_left` for the settle phase."""
    return judge_success(np.asarray(object_state)[-1], rule) and hand_left(times, contact_force, rule)


def rule_text(rule: SuccessConfig) -> str:
    """The rule in a few characters for tables: ``lid_hinge >= 1.7``."""
    if rule.above is not None:
        return f"{rule.joint} >= {rule.above:g}"
    return f"{rule.joint} <= {rule.below:g}"


def verdict_why(times, object_state, contact_force, rule: SuccessConfig) -> str:
    """Why :func:`judge_run` decided as it did, in a few words for a person watching:
    ``lid_hinge 1.82 (rule >= 1.7), the hand left`` or ``... the hand still touched the scene``."""
    final = float(np.asarray(object_state)[-1])
    bound = f">= {rule.above:g}" if rule.above is not None else f"<= {rule.below:g}"
    left = ("the hand left" if hand_left(times, contact_force, rule)
            else f"the hand still touched the scene in the last {rule.settle_time:g} s")
    return f"{rule.joint} {final:.3f} (rule {bound}), {left}"
