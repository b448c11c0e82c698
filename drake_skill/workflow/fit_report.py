"""``fit_report.html``: what the camera, the goal model and the DMPs made of each demonstration.

``drake-skill fit`` writes it into the fitted folder: one self-contained page
(images inline, opened by a browser with no server) and one terminal line per
finding (``warning: DEMO: what, when; how to fix``). Per demonstration:

- **the segment over time.** The scene of the recording is posed again on the
  scenario's simulated station from the demonstration's own record (arm
  joints, fingers, the object's true pose and joint, every ``every_s``
  seconds), the object camera rendered and segmented with the station's
  segmenter settings, the table plane fitted on the first frame as the
  segmenter does. Per frame: the object's visible pixels (the renderer's
  label image, as ``skills --check-camera``), the object-coloured pixels of
  the crop (the segmenter's colour test) and the pixels the segment keeps on
  the object. Kept / visible below :data:`KEPT_WARN` for
  :data:`MIN_WARN_S` or longer is a warning: where the object's pixels
  fail the colour test, widen the colour range; where they pass it and the
  segment still drops them, the clustering does (``cluster_rule``). Three
  frames (start, when the object first moves, end) are shown with the
  segment drawn over them: kept green, object-coloured but dropped red,
  object but not object-coloured blue;
- the goal features G (the PCA of the PCAE codes, thesis section 4.2) and the
  goal model's most likely state over time (smoothed posterior);
- how far the executed imitation is from the demonstration [mm RMS], before and
  after refinement (``skill.info["dmp_refinement"]``);
- the peak filtered contact force and when (the recorder's, ``demos/force_margin``).

The re-posed scene is the simulation's: a demonstration recorded on the robot
(``metadata["source"] == "robot"``) is reported without the segment panel.
Demonstrations that store no perception have no goal panel.
"""

from __future__ import annotations

import dataclasses as dc
import html
from pathlib import Path

import numpy as np

from drake_skill.fileio import atomic_write_text, png_data_url

__all__ = ["KEPT_WARN", "MIN_WARN_S", "SegmentTrack", "segment_tracks", "segment_warnings", "track_segment",
           "write_fit_report"]

#: A stretch of frames keeping less than this fraction of the object's visible pixels is warned about.
KEPT_WARN = 0.5
#: ... when it lasts at least this long [s].
MIN_WARN_S = 0.5
#: Object pixels that fail the colour test: above this share of the lost ones, the fix is the colour range.
COLOUR_CAUSE = 0.5


@dc.dataclass
class SegmentTrack:
    """One demonstration's segment over time: times (N,) [s]; per frame the object's visible pixels,
    those of them that pass the colour test, those the segment keeps; ``snapshots``: (what, t [s],
    (h, w, 3) uint8 image with the segment drawn over it)."""

    times: np.ndarray
    visible: np.ndarray
    coloured: np.ndarray
    kept: np.ndarray
    snapshots: list = dc.field(default_factory=list)

    @property
    def kept_fraction(self) -> np.ndarray:
        return self.kept / np.maximum(self.visible, 1)


def _overlay(rgb: np.ndarray, truth: np.ndarray, coloured: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """The crop with the segment drawn over it (module docstring's colours, half blended)."""
    out = rgb.astype(float)
    for mask, colour in ((kept, (0, 200, 0)), (coloured & ~kept, (230, 0, 0)), (truth & ~coloured, (0, 80, 255))):
        out[mask] = 0.5 * out[mask] + 0.5 * np.array(colour, dtype=float)
    return out.astype(np.uint8)


class _Poser:
    """The station posed at a demonstration's recorded state: a scratch context, no simulation."""

    def __init__(self, station, demo):
        from drake_skill.perception.systems import segmenter_config_for_station
        from drake_skill.skills.camera_check import object_labels
        from drake_skill.station.recording import vector_to_pose

        self.station, self.demo = station, demo
        self.seg = segmenter_config_for_station(station.config, station.object_camera.window).segmentation
        self.labels = object_labels(station)
        self.context = station.CreateDefaultContext()
        station.set_object_pose(self.context, vector_to_pose(demo.X_WO_true))
        self.plane = None

    def pose(self, t: float) -> None:
        d, station = self.demo, self.station
        at = lambda values: np.array([np.interp(t, d.times_100hz, c) for c in np.atleast_2d(values.T)])  # noqa: E731
        plant = station.plant
        plant_context = plant.GetMyMutableContextFromRoot(self.context)
        plant.SetPositions(plant_context, station.panda, at(d.q_100hz))
        plant.SetPositions(plant_context, station.hand, np.full(2, 0.5 * float(at(d.gripper_100hz)[0])))
        station.set_object_joint(self.context, float(at(d.object_state_100hz)[0]))

    def frame(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(rgb (h, w, 3), object truth, colour test, segment) of the object camera's crop, by
        ``skills --check-camera``'s functions (the segment on the object's pixels alone)."""
        from drake_skill.skills.camera_check import fit_plane, frame_pixels, object_truth

        station, context = self.station, self.context
        if self.plane is None:
            self.plane = fit_plane(station, context, self.seg, 0)
        pixels = frame_pixels(station, context, self.seg, self.plane)
        truth = object_truth(station, context, self.labels)
        return pixels.rgb, truth, pixels.coloured & truth, pixels.kept & truth


def _snapshot_times(demo) -> list[tuple[str, float]]:
    """Start, the first time the object's joint moved 2 % of its travel over the demonstration, end."""
    t, s = demo.times_100hz - demo.times_100hz[0], np.asarray(demo.object_state_100hz, dtype=float)
    travel = float(np.max(np.abs(s - s[0])))
    moved = np.flatnonzero(np.abs(s - s[0]) > 0.02 * travel) if travel > 0 else np.zeros(0, int)
    first = float(t[moved[0]]) if moved.size else float(t[len(t) // 2])
    return [("start", 0.0), ("object first moves", first), ("end", float(t[-1]))]


def track_segment(station, demo, every_s: float = 0.5) -> SegmentTrack:
    """The segment of ``demo``'s recorded scene every ``every_s`` seconds on ``station`` (a simulated
    station with its camera; module docstring)."""
    poser = _Poser(station, demo)
    t0 = float(demo.times_100hz[0])
    duration = float(demo.times_100hz[-1]) - t0
    times = np.append(np.arange(0.0, duration, every_s), duration)
    counts = []
    for t in times:
        poser.pose(t0 + t)
        _, truth, coloured, kept = poser.frame()
        counts.append((truth.sum(), coloured.sum(), kept.sum()))
    snapshots = []
    for what, t in _snapshot_times(demo):
        poser.pose(t0 + t)
        snapshots.append((what, t, _overlay(*poser.frame())))
    visible, coloured, kept = (np.array(c, dtype=int) for c in zip(*counts))
    return SegmentTrack(times, visible, coloured, kept, snapshots)


def segment_warnings(name: str, track: SegmentTrack) -> list[str]:
    """One line per stretch of at least :data:`MIN_WARN_S` keeping under :data:`KEPT_WARN` of the object."""
    low = track.kept_fraction < KEPT_WARN
    out, k = [], 0
    while k < len(low):
        if not low[k]:
            k += 1
            continue
        end = k
        while end + 1 < len(low) and low[end + 1]:
            end += 1
        if track.times[end] - track.times[k] >= MIN_WARN_S - 1e-9:
            out.append(_warning(name, track, k, end))
        k = end + 1
    return out


def _warning(name: str, track: SegmentTrack, k: int, end: int) -> str:
    part = slice(k, end + 1)
    kept = float(np.sum(track.kept[part]) / max(np.sum(track.visible[part]), 1))
    lost = np.sum(track.visible[part] - track.kept[part])
    uncoloured = np.sum(track.visible[part] - track.coloured[part])
    if lost and uncoloured / lost > COLOUR_CAUSE:
        fix = ("most of the lost pixels fail the colour test: widen the scenario's object colour range "
               "(object.colour value_min, saturation_min or the hue range)")
    else:
        fix = ("the lost pixels pass the colour test and the segment drops them: keep every region "
               "(object.colour.cluster_rule: all_regions) or move the camera")
    until = "the end" if end == len(track.times) - 1 else f"t = {track.times[end]:.1f} s"
    return (f"{name}, from t = {track.times[k]:.1f} s to {until}: the segment keeps {kept * 100:.0f} % of the "
            f"object's visible pixels; {fix}")


def segment_tracks(skill, demos, station_config=None) -> tuple[dict, list[str]]:
    """(name -> :class:`SegmentTrack` of each simulated demonstration, the warning lines) on the scenario
    ``station_config`` (default the skill's); none where the scenario has no camera."""
    from drake_skill.station.sim.builder import build_station

    config = station_config if station_config is not None else skill.station_config()
    if not config.enable_camera:
        return {}, []
    station = build_station(config)
    tracks, warnings = {}, []
    for i, demo in enumerate(demos):
        if demo.metadata.get("source") == "robot":
            continue
        name = _demo_name(demo, i)
        tracks[name] = track_segment(station, demo)
        warnings += segment_warnings(name, tracks[name])
    return tracks, warnings


# ----------------------------------------------------------------------------- the page
def _demo_figure(skill, demo, track: SegmentTrack | None) -> str:
    """The kept fraction, the goal features and the goal model's state over time, as one PNG."""
    from drake_skill.fileio import new_figure

    rows = (track is not None) + 2 * (demo.object_points is not None)
    if rows == 0:
        return ""
    fig = new_figure((8, 2.2 * rows))
    axes = [fig.add_subplot(rows, 1, i + 1) for i in range(rows)]
    i = 0
    if track is not None:
        ax = axes[i]
        i += 1
        ax.plot(track.times, track.kept_fraction, label="kept / visible")
        ax.plot(track.times, track.coloured / np.maximum(track.visible, 1), "--", label="object-coloured / visible")
        ax.axhline(KEPT_WARN, color="red", lw=0.8, ls=":", label="warning below")
        ax.set_ylim(-0.05, 1.05)
        ax.set_ylabel("object pixels")
        ax.legend(loc="lower left", fontsize=7)
    if demo.object_points is not None:
        G = skill.goal_data(demo.object_points, demo.perception_valid, X_WO=demo.X_WO_start)
        t = demo.times - demo.times[0]
        axes[i].plot(t[:len(G)], G)
        axes[i].set_ylabel("goal features G")
        _, smoothed, _ = skill.pomrp.posteriors(G)
        axes[i + 1].step(t[:len(G)], np.argmax(smoothed, axis=1), where="post")
        axes[i + 1].set_ylabel("goal model state")
        axes[i + 1].set_yticks(range(smoothed.shape[1]))
    axes[-1].set_xlabel("time from the demonstration's start [s]")
    fig.tight_layout()
    return f'<img alt="over time" src="{png_data_url(fig=fig)}">'


def _facts(demo, refinement: dict | None) -> str:
    facts = []
    if refinement is not None:
        errors = refinement["errors_mm"]
        facts.append(f"imitation {errors[0]:.1f} mm RMS from the demonstration, {min(errors):.1f} mm after "
                     f"refinement" + (" (the plain fit kept)" if refinement.get("kept_plain") else ""))
    if "peak_contact_force_N" in demo.metadata:
        facts.append(f"peak contact force {demo.metadata['peak_contact_force_N']:.1f} N at "
                     f"t = {demo.metadata.get('peak_contact_force_time_s', float('nan')):.1f} s")
    facts.append(f"ground truth: {'success' if demo.success else 'failure'}, final state {demo.final_object_state:.4g}")
    return "<ul>" + "".join(f"<li>{html.escape(f)}</li>" for f in facts) + "</ul>"


def _snapshots(track: SegmentTrack) -> str:
    return "".join(f'<figure><img alt="{html.escape(w)}" src="{png_data_url(img)}"><figcaption>{html.escape(w)}, '
                   f"t = {t:.1f} s</figcaption></figure>" for w, t, img in track.snapshots)


_STYLE = """body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}figure{display:inline-block;
margin:.4em;font-size:.85em;vertical-align:top}figure img{width:300px;border:1px solid #999}.warn{color:#a00}"""

_LEGEND = ("Segment drawn over the object camera's crop: <span style='color:#0a0'>kept</span>, "
           "<span style='color:#d00'>object-coloured but dropped</span>, "
           "<span style='color:#05f'>object but not object-coloured</span>.")


def write_fit_report(path, skill, demos, tracks: dict, warnings: list[str]) -> Path:
    """Writes the page (module docstring) to ``path``. ``tracks``: demonstration name -> SegmentTrack (or
    None where none was made); ``warnings``: the fit's warning lines, shown at the top."""
    refinement = list(skill.info.get("dmp_refinement", []))     # one per demonstration, the fit's order
    body = [f"<h1>Fit of '{html.escape(skill.name)}' from {len(demos)} demonstrations</h1>"]
    body += [f"<p class='warn'>warning: {html.escape(w)}</p>" for w in warnings] or ["<p>No warnings.</p>"]
    body.append(f"<p>{_LEGEND}</p>")
    for i, demo in enumerate(demos):
        name = _demo_name(demo, i)
        track = tracks.get(name)
        body += [f"<h2>{html.escape(name)}</h2>", _facts(demo, refinement[i] if i < len(refinement) else None),
                 _snapshots(track) if track is not None else "<p>(no segment panel: "
                 "a robot's demonstration, or a scenario without the camera)</p>",
                 _demo_figure(skill, demo, track)]
    page = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>fit of {html.escape(skill.name)}</title>"
            f"<style>{_STYLE}</style></head><body>{''.join(body)}</body></html>\n")
    return atomic_write_text(path, page)


def _demo_name(demo, i: int) -> str:
    return Path(demo.path).stem if demo.path else f"demo_{i:03d}"
