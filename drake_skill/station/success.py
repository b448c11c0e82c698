"""Ground-truth success judges (simulation only; never used as a reward).

docs/method.md section 4: reported success rates in simulation use the simulator's
ground truth. The station's ``object_state`` port gives the lid angle [rad]
(box) or drawer travel [m] (drawer); a skill succeeds when, at the end of the
execution, it is on the right side of the configured threshold.
"""

from __future__ import annotations

from drake_skill.station.config import SKILLS, SuccessConfig

OBJECT_FOR_SKILL = {"open": "box", "close": "box", "draw": "drawer"}


def judge_success(skill: str, object_state: float, config: SuccessConfig | None = None) -> bool:
    """True if the final ``object_state`` completes ``skill``.

    open: lid angle >= open_min; close: lid angle <= close_max;
    draw: drawer travel >= draw_min.
    """
    config = config or SuccessConfig()
    value = float(object_state)
    if skill == "open":
        return value >= config.open_min
    if skill == "close":
        return value <= config.close_max
    if skill == "draw":
        return value >= config.draw_min
    raise ValueError(f"skill {skill!r}: expected one of {', '.join(SKILLS)}")
