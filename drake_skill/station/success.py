"""Ground-truth success judges (simulation only; never used as a reward).

docs/method.md section 4: reported success rates in simulation use the simulator's
ground truth. The station's ``object_state`` port gives the lid angle [rad]
(box) or drawer travel [m] (drawer). The verdict reads the state at the end
of a settle phase (``SuccessConfig.settle_time``) in which the hand holds
still away from the object:

* open: lid angle >= ``open_min``, past the lid's tipping angle, so a lid
  judged open stays open by its own weight once the hand has left;
* close: lid angle <= ``close_max`` (shut);
* draw: drawer travel >= ``draw_min``.

A run whose hand still touches the scene during the settle phase fails: the
object's state is then held by the hand, not by itself.
"""

from __future__ import annotations

import numpy as np

from drake_skill.station.config import SKILLS, SuccessConfig

OBJECT_FOR_SKILL = {"open": "box", "close": "box", "draw": "drawer"}
#: Contact force below this counts as "not touching" in the settle phase [N].
TOUCH_FORCE_N = 1e-3


def judge_success(skill: str, object_state: float, config: SuccessConfig | None = None) -> bool:
    """True if the final ``object_state`` completes ``skill`` (the thresholds above)."""
    config = config or SuccessConfig()
    value = float(object_state)
    if skill == "open":
        return value >= config.open_min
    if skill == "close":
        return value <= config.close_max
    if skill == "draw":
        return value >= config.draw_min
    raise ValueError(f"skill {skill!r}: expected one of {', '.join(SKILLS)}")


def hand_left(times, contact_force, config: SuccessConfig | None = None) -> bool:
    """True if the robot touched nothing in the last ``settle_time`` s of the run
    (``contact_force``: (T,) peak robot-scene force per sample [N])."""
    config = config or SuccessConfig()
    times, force = np.asarray(times, dtype=float), np.asarray(contact_force, dtype=float)
    settle = times >= times[-1] - config.settle_time + 1e-9
    return bool(np.all(force[settle] < TOUCH_FORCE_N))


def judge_run(skill: str, times, object_state, contact_force, config: SuccessConfig | None = None) -> bool:
    """The verdict of a recorded run: :func:`judge_success` on the last object
    state, and :func:`hand_left` for the settle phase."""
    return (judge_success(skill, np.asarray(object_state)[-1], config)
            and hand_left(times, contact_force, config))
