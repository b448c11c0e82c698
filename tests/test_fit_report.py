"""The fit report's segment check (issue 51 item 2): a colour range that cuts a face of a moving part
is a warning naming the demonstration, the time and the fix; the shipped colour range gives none."""

import re

import numpy as np
import pytest

from drake_skill.demos.format import Demonstration
from drake_skill.skills import scenario_for_skill
from drake_skill.station.recording import pose_to_vector
from drake_skill.station.sim.builder import build_station
from drake_skill.workflow.fit_report import SegmentTrack, segment_warnings, track_segment


def _lid_opening(station, config) -> Demonstration:
    """3 s at 100 Hz: the arm at home, Open's lid swung from 0 to 1.9 rad in 2 s, then held."""
    t = np.linspace(0.0, 3.0, 301)
    pose = np.tile([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], (301, 1))
    return Demonstration(skill="open", seed=0, success=True, final_object_state=1.9, times_100hz=t,
                         X_OE_100hz=pose, q_100hz=np.tile(config.q_home, (301, 1)), gripper_100hz=np.full(301, 0.02),
                         object_state_100hz=np.minimum(np.linspace(0.0, 2.85, 301), 1.9), times=t[::10],
                         X_OE=pose[::10], X_WO_true=pose_to_vector(station.nominal_object_pose()))


@pytest.mark.parametrize("value_min", [None, 0.5])
def test_a_colour_range_cutting_the_opened_lid_is_a_warning(value_min):
    config = scenario_for_skill("open")
    if value_min is not None:        # the opened lid's shaded faces fall under it
        config.object.colour.value_min = value_min
    station = build_station(config)
    track = track_segment(station, _lid_opening(station, config), every_s=0.25)
    assert len(track.times) == 13 and [w for w, _, _ in track.snapshots] == ["start", "object first moves", "end"]
    assert track.snapshots[1][1] == pytest.approx(0.05) and track.snapshots[2][0:2] == ("end", 3.0)
    warnings = segment_warnings("demo_000", track)
    if value_min is None:
        assert warnings == [] and track.kept_fraction.min() > 0.95
        return
    assert track.kept_fraction[-1] < 0.1 and track.kept_fraction[3] > 0.5
    (warning,) = warnings
    assert re.fullmatch(r"demo_000, from t = 1\.[5-9] s to the end: the segment keeps \d % of the object's visible "
                        r"pixels; most of the lost pixels fail the colour test: widen the scenario's object colour "
                        r"range \(object\.colour value_min, saturation_min or the hue range\)", warning), warning
    # The end's picture draws the object's pixels that fail the colour test in blue.
    image = track.snapshots[2][2].astype(int)
    assert np.sum((image[:, :, 2] > image[:, :, 0] + 60) & (image[:, :, 2] > image[:, :, 1])) > 500


def _track(kept, coloured, every=0.25):
    kept, coloured = np.asarray(kept), np.asarray(coloured)
    return SegmentTrack(np.arange(len(kept)) * every, np.full(len(kept), 100), coloured, kept)


def test_short_stretches_are_not_warned_and_the_cause_picks_the_fix():
    assert segment_warnings("d", _track([100, 10, 100, 10, 10, 100], [100] * 6)) == []    # 0 s and 0.25 s
    (dropped,) = segment_warnings("d", _track([100, 10, 10, 10, 100], [100] * 5))
    assert dropped.startswith("d, from t = 0.2 s to t = 0.8 s: the segment keeps 10 % of the object's visible")
    assert "pass the colour test and the segment drops them: keep every region" in dropped
    (uncoloured,) = segment_warnings("d", _track([100, 0, 0, 0], [100, 0, 0, 0]))
    assert "to the end: the segment keeps 0 %" in uncoloured and "fail the colour test" in uncoloured
