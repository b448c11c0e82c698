"""The fit report's segment check (issue 51 item 2): a colour range that cuts a face of a moving part
is a warning naming the demonstration, the time and the fix; the shipped colour range gives none."""

import re

import numpy as np
import pytest

from drake_skill.demos.format import Demonstration
from drake_skill.skills import scenario_for_skill
from drake_skill.station.recording import pose_to_vector
from drake_skill.station.make import make_station
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
    station = make_station(config)
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


def _stored(source: str, coloured_from: int = 81, kept_from: int = 81) -> Demonstration:
    """8 s of a schema-2 file: 81 frames of 20,000 pixels of the object's hue, all object-coloured and 99 %
    kept; 2 % object-coloured from frame ``coloured_from`` on, 2 % kept from ``kept_from``; pictures at 0, 3.0
    and 8.0 s. No ground-truth scene: nothing to re-pose."""
    t = np.linspace(0.0, 8.0, 801)
    pose = np.tile([0.5, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], (801, 1))
    hue = np.full(81, 20_000)
    coloured = np.where(np.arange(81) < coloured_from, hue, 400)
    kept = np.minimum(np.where(np.arange(81) < kept_from, 19_800, 400), coloured)
    rgb = np.full((3, 6, 8, 3), 90, dtype=np.uint8)
    segment = np.zeros((3, 6, 8), dtype=np.uint8)
    segment[0, 1:5, 2:6] = 3                                  # kept at the start
    segment[2, 1:5, 2:4], segment[2, 1:5, 4:6] = 1, 2         # the end: of the hue, not coloured; coloured, dropped
    return Demonstration(skill="open", seed=0, success=True, final_object_state=1.9, times_100hz=t, X_OE_100hz=pose,
                         q_100hz=np.zeros((801, 7)), gripper_100hz=np.zeros(801), object_state_100hz=t / 4,
                         times=t[::10], X_OE=pose[::10], X_WO_true=pose[0], X_WO_start=pose[0],
                         object_points=np.zeros((81, 2048, 3), np.float32), perception_valid=np.zeros(81, bool),
                         peak_force=np.where(np.arange(81) >= 30, 2.0, 0.0), pixels_hue=hue, pixels_coloured=coloured,
                         pixels_kept=kept, snapshot_index=np.array([0, 30, 80]), snapshot_rgb=rgb,
                         snapshot_segment=segment,
                         metadata={"source": source, "snapshot_labels": ["start", "first contact", "end"]})


def test_a_schema_2_demo_is_reported_from_its_stored_counts_and_frames(tmp_path, monkeypatch):
    """The segment losing the object from 6.6 s is a warning from the file alone, its cause read from the
    counts (the colour range, or the segment dropping object-coloured pixels): no station is built, no scene
    re-posed, and a robot's demonstration gets its panel too."""
    from types import SimpleNamespace

    import drake_skill.station.make as make
    from drake_skill.workflow.fit_report import HUE, segment_tracks, write_fit_report

    def no_reposing(*args, **kwargs):
        raise AssertionError("a schema-2 demonstration was re-posed")

    monkeypatch.setattr(make, "make_station", no_reposing)
    skill = SimpleNamespace(name="open", info={}, station_config=no_reposing,
                            goal_data=lambda points, valid, X_WO=None: np.zeros((len(points), 2)),
                            pomrp=SimpleNamespace(posteriors=lambda G: (None, np.full((len(G), 2), 0.5), None)))
    demos = [_stored("scripted", coloured_from=66), _stored("kinesthetic", kept_from=70), _stored("kinesthetic")]
    tracks, warnings = segment_tracks(skill, demos)
    assert warnings == [
        "demo_000, from t = 6.6 s to the end: the segment keeps 2 % of the pixels of the object's hue; most of the "
        "lost pixels fail the colour test: widen the scenario's object colour range (object.colour value_min, "
        "saturation_min or the hue range)",
        "demo_001, from t = 7.0 s to the end: the segment keeps 2 % of the pixels of the object's hue; the lost "
        "pixels pass the colour test and the segment drops them: keep every region (object.colour.cluster_rule: "
        "all_regions) or move the camera"]
    track = tracks["demo_000"]
    assert track.of == tracks["demo_002"].of == HUE and tracks["demo_002"].kept_fraction.min() == pytest.approx(0.99)
    assert [(w, t) for w, t, _ in track.snapshots] == [("start", 0.0), ("first contact", 3.0), ("end", 8.0)]
    start, end = track.snapshots[0][2].astype(int), track.snapshots[2][2].astype(int)
    assert start[2, 3].tolist() == [45, 145, 45] and start[0, 0].tolist() == [90, 90, 90]   # kept green, the rest
    assert end[2, 3].tolist() == [45, 85, 172] and end[2, 4].tolist() == [160, 45, 45]      # blue, red
    page = write_fit_report(tmp_path / "fit_report.html", skill, demos, tracks, warnings).read_text()
    assert page.count("<figure>") == 9 and "first contact, t = 3.0 s" in page and "no segment panel" not in page
    assert "from t = 6.6 s to the end: the segment keeps 2 % of the pixels of the object&#x27;s hue" in page


def test_a_recording_whose_colour_range_cuts_the_boxs_shaded_faces_warns_from_its_stored_counts():
    """Schema 2 on a rendered scene: Open's closed box (seed 0) at value_min 0.5 for 1 s. A third of the pixels of
    the box's hue pass the colour test (its lit top; 6,786 of 20,171 measured), and the warning says so, from
    the file's counts alone."""
    from types import SimpleNamespace

    from drake_skill.demos.demonstrator import demonstration_from
    from drake_skill.station.pose_source import hold_plan
    from drake_skill.station.sim.simulation import StationSimulation
    from drake_skill.workflow.fit_report import segment_tracks

    config = scenario_for_skill("open")
    config.object.colour.value_min = 0.5
    sim = StationSimulation(config, perceive=True)
    X_WO = sim.reset(0)
    sim.set_plan(hold_plan(sim.home_pose()))
    demo = demonstration_from(sim.record(100), 100.0, 10.0, "open", 0, X_WO, success=False,
                              metadata={"source": "scripted"})
    assert np.all(demo.pixels_coloured < 0.4 * demo.pixels_hue)
    assert np.all(demo.pixels_kept > 0.95 * demo.pixels_coloured)
    _, warnings = segment_tracks(SimpleNamespace(), [demo])        # no skill: nothing is re-posed
    (warning,) = warnings
    assert re.fullmatch(r"demo_000, from t = 0\.0 s to the end: the segment keeps 3\d % of the pixels of the object's "
                        r"hue; most of the lost pixels fail the colour test: widen the scenario's object colour range "
                        r"\(object\.colour value_min, saturation_min or the hue range\)", warning), warning
