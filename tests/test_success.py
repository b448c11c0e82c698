"""Ground-truth success judges (drake_skill.station.success): thresholds and the settle rule.

Recorded runs are written out by hand (times, object state, peak robot-scene
contact force per sample, as the station's recorder gives them), so the
settle rule is exercised by runs that must fail it.
"""

import dataclasses as dc

import numpy as np
import pytest

from drake_skill.station.scenario import SuccessConfig
from drake_skill.skills import load_skill
from drake_skill.station.success import TOUCH_FORCE_N, hand_left, judge_run, judge_success

#: A 5 s Close recorded at 100 Hz: the lid shuts by 3 s. With the default 1 s
#: settle time the settle phase is the samples after t = 4 s (a sample's force is
#: the peak over the interval that ends at it: the one at 4.00 s covers 3.99-4.00 s).
TIMES = np.round(np.arange(0, 501) * 0.01, 10)
SHUT = np.where(TIMES < 3.0, 1.0 - TIMES / 3.0, 0.0)


def _touching(first, last, force=5.0):
    """Contact force [N] of a hand on the lid in the samples first <= t <= last, 0 elsewhere."""
    return np.where((TIMES >= first - 1e-9) & (TIMES <= last + 1e-9), force, 0.0)


def _rule(skill):
    return load_skill(skill).success


CLOSE = SuccessConfig(joint="lid_hinge", below=0.05)


def test_thresholds_of_each_shipped_skill():
    opened, closed, drawn = _rule("open"), _rule("close"), _rule("draw")
    assert (opened.joint, closed.joint, drawn.joint) == ("lid_hinge", "lid_hinge", "drawer_slide")
    assert (opened.above, closed.below, drawn.above) == (1.7, 0.05, 0.10)
    assert judge_success(opened.above, opened) and not judge_success(opened.above - 1e-6, opened)
    assert judge_success(closed.below, closed) and not judge_success(closed.below + 1e-6, closed)
    assert judge_success(drawn.above, drawn) and not judge_success(drawn.above - 1e-6, drawn)
    with pytest.raises(ValueError, match="no joint"):
        judge_success(0.0, SuccessConfig())


def test_a_hand_still_on_the_lid_in_the_settle_phase_fails():
    """The lid ends shut either way; only the run whose hand left before the settle phase succeeds."""
    assert judge_success(SHUT[-1], CLOSE)
    left = _touching(1.0, 3.5)               # pushes the lid shut, lets go at 3.5 s
    assert hand_left(TIMES, left, CLOSE) and judge_run(TIMES, SHUT, left, CLOSE)
    held = _touching(1.0, 4.5)               # still holds the lid down at 4.0-4.5 s
    assert not hand_left(TIMES, held, CLOSE) and not judge_run(TIMES, SHUT, held, CLOSE)
    # One sample of contact anywhere in the settle phase is enough, the first and last included.
    for t in (4.01, 4.5, 5.0):
        assert not judge_run(TIMES, SHUT, _touching(t, t), CLOSE), t
    # Contact that ends with the sample before the settle phase does not count.
    assert judge_run(TIMES, SHUT, _touching(1.0, 4.0), CLOSE)
    # A lid left open fails however still the hand is.
    assert not judge_run(TIMES, np.full_like(TIMES, 0.5), np.zeros_like(TIMES), CLOSE)


def test_the_settle_phase_is_the_last_settle_time_seconds():
    touch = _touching(1.0, 3.5)
    assert judge_run(TIMES, SHUT, touch, dc.replace(CLOSE, settle_time=1.0))
    assert not judge_run(TIMES, SHUT, touch, dc.replace(CLOSE, settle_time=2.0))   # from 3.0 s
    # Runs that do not start at 0 (a recorder anchored later): the phase is measured from the end.
    assert judge_run(TIMES + 7.0, SHUT, touch, CLOSE) and not judge_run(TIMES + 7.0, SHUT, _touching(1.0, 4.5),
                                                                         CLOSE)


def test_touch_threshold():
    below = _touching(4.01, 5.0, force=0.5 * TOUCH_FORCE_N)
    above = _touching(4.01, 5.0, force=2.0 * TOUCH_FORCE_N)
    assert judge_run(TIMES, SHUT, below, CLOSE) and not judge_run(TIMES, SHUT, above, CLOSE)
