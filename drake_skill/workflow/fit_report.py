"""``fit_report.html``: what the camera, the goal model and the DMPs made of each demonstration.

``drake-skill fit`` writes it into the fitted folder: one self-contained page
(images inline, opened by a browser with no server) and one terminal line per
finding (``warning: DEMO: what, when; how to fix``). Per demonstration:

- **the segment over time.** A demonstration file of schema 2 stores it
  (``drake_skill.demos.format``): per 10 Hz frame the camera image's pixels
  of the object's hue (the colour test widened, ``hue_config``: without
  ground truth they stand for the object's pixels), the object-coloured ones
  and those the segment kept, and three small frames (start, first contact,
  end) with the segment. No station is built and no scene re-posed, so a
  demonstration recorded on the robot gets the panel too; the kept fraction
  is kept / of the object's hue, and the cause of a loss is read as below
  (of the object's hue but not object-coloured: the colour range). Other
  things of the object's hue in the view lower it.
  For a schema-1 file the scene of the recording is posed again on the
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
- the peak filtered contact force and when (the recording's, ``demos/force_margin``).

The re-posed scene is the simulation's: a schema-1 demonstration recorded on the
robot (``metadata["source"]`` "kinesthetic") is reported without the segment
panel. Demonstrations that store no perception have no goal panel.
"""

from __future__ import annotations

import dataclasses as dc
import html
from pathlib import Path

import numpy as np

from drake_skill.fileio import atomic_write_text, png_data_url

__all__ = ["HUE", "KEPT_WARN", "MIN_WARN_S", "VISIBLE", "SegmentTrack", "segment_tracks", "segment_warnings",
           "stored_track", "track_segment", "write_fit_report"]

#: A stretch of frames keeping less than this fraction of the object's pixels (visible, or of its hue) is
#: warned about ...
KEPT_WARN = 0.5
#: ... when it lasts at least this long [s].
MIN_WARN_S = 0.5
#: Object pixels that fail the colour test: above this share of the lost ones, the fix is the colour range.
COLOUR_CAUSE = 0.5
#: What a track's kept fraction is of: a re-posed scene's object pixels (the renderer's labels) ...
VISIBLE = "the object's visible pixels"
#: ... or a schema-2 file's stored pixels of the object's hue.
HUE = "the pixels of the object's hue"
#: metadata["source"] of a demonstration recorded on the robot (drake-skill hardware record-demo).
ROBOT_SOURCES = ("kinesthetic", "robot")


@dc.dataclass
class SegmentTrack:
    """One demonstration's segment over time: times (N,) [s]; per frame the pixels the kept fraction is
    of (``visible``: :data:`VISIBLE` of a re-posed scene, or :data:`HUE` stored in the file, as
    ``of`` says), those of them that pass the colour test, those the segment keeps; ``snapshots``:
    (what, t [s], (h, w, 3) uint8 image with the segment drawn over it)."""

    times: np.ndarray
    visible: np.ndarray
    coloured: np.ndarray
    kept: np.ndarray
    snapshots: list = dc.field(default_factory=list)
    of: str = VISIBLE

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
    from drake_skill.demos.format import first_move

    t = demo.times_100hz - demo.times_100hz[0]
    moved = first_move(demo.object_state_100hz)
    first = float(t[moved if moved is not None else len(t) // 2])
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


def stored_track(demo) -> SegmentTrack:
    """The segment of a schema-2 demonstration (``demo.has_segment``) from its stored counts and frames:
    no simulation, so a robot's demonstration too. The kept fraction is of :data:`HUE`; the frames
    show kept pixels green, object-coloured but dropped ones red, and those of the object's hue that
    fail the colour test blue."""
    t = demo.times - demo.times[0]
    hue, coloured, kept = (c.astype(int) for c in (demo.pixels_hue, demo.pixels_coloured, demo.pixels_kept))
    labels = demo.metadata.get("snapshot_labels", ["start", "first contact", "end"])
    snapshots = [(what, float(t[k]), _overlay(rgb, segment >= 1, segment >= 2, segment == 3))
                 for what, k, rgb, segment in zip(labels, demo.snapshot_index, demo.snapshot_rgb,
                                                  demo.snapshot_segment)]
    return SegmentTrack(t, hue, coloured, kept, snapshots, of=HUE)


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
    return (f"{name}, from t = {track.times[k]:.1f} s to {until}: the segment keeps {kept * 100:.0f} % of "
            f"{track.of}; {fix}")


def segment_tracks(skill, demos, station_config=None) -> tuple[dict, list[str]]:
    """(name -> :class:`SegmentTrack` of each demonstration that has one, the warning lines): a schema-2
    file's stored one (:func:`stored_track`), else, for a simulated demonstration, its scene re-posed
    on the scenario ``station_config`` (default the skill's; none where the scenario has no camera)."""
    tracks, warnings, repose = {}, [], _Reposer(skill, station_config)
    for i, demo in enumerate(demos):
        name = _demo_name(demo, i)
        track = stored_track(demo) if demo.has_segment else repose(demo)
        if track is not None:
            tracks[name] = track
            warnings += segment_warnings(name, track)
    return tracks, warnings


class _Reposer:
    """:func:`track_segment` of a schema-1 simulated demonstration (None for a robot's or without the
    camera), the station built at the first one."""

    def __init__(self, skill, station_config=None):
        self.skill, self.config, self.station = skill, station_config, None

    def __call__(self, demo) -> SegmentTrack | None:
        from drake_skill.station.make import make_station

        if demo.metadata.get("source") in ROBOT_SOURCES:
            return None
        if self.config is None:
            self.config = self.skill.station_config()
        if not self.config.enable_camera:
            return None
        if self.station is None:
            self.station = make_station(self.config)
        return track_segment(self.station, demo)


# ----------------------------------------------------------------------------- the page
def _demo_figure(skill, demo, track: SegmentTrack | None) -> str:
    """The kept fraction, the peak contact force (schema 2), the goal features and the goal model's state
    over time, as one PNG."""
    from drake_skill.fileio import new_figure

    panels = ([lambda ax: _segment_panel(ax, track)] if track is not None else []) \
        + ([lambda ax: _force_panel(ax, demo)] if demo.peak_force is not None else [])
    if demo.object_points is not None:
        panels += _goal_panels(skill, demo)
    if not panels:
        return ""
    fig = new_figure((8, 2.2 * len(panels)))
    for i, draw in enumerate(panels):
        draw(fig.add_subplot(len(panels), 1, i + 1))
    fig.axes[-1].set_xlabel("time from the demonstration's start [s]")
    fig.tight_layout()
    return f'<img alt="over time" src="{png_data_url(fig=fig)}">'


def _segment_panel(ax, track: SegmentTrack) -> None:
    of = "visible" if track.of == VISIBLE else "of the object's hue"
    ax.plot(track.times, track.kept_fraction, label=f"kept / {of}")
    ax.plot(track.times, track.coloured / np.maximum(track.visible, 1), "--", label=f"object-coloured / {of}")
    ax.axhline(KEPT_WARN, color="red", lw=0.8, ls=":", label="warning below")
    ax.set_ylim(-0.05, 1.05)
    ax.set_ylabel("object pixels")
    ax.legend(loc="lower left", fontsize=7)


def _goal_panels(skill, demo) -> list:
    """Drawers of the goal features G and of the goal model's most likely state over time."""
    G = skill.goal_data(demo.object_points, demo.perception_valid, X_WO=demo.X_WO_start)
    t = (demo.times - demo.times[0])[:len(G)]
    smoothed = skill.pomrp.posteriors(G)[1]

    def features(ax) -> None:
        ax.plot(t, G)
        ax.set_ylabel("goal features G")

    def states(ax) -> None:
        ax.step(t, np.argmax(smoothed, axis=1), where="post")
        ax.set_ylabel("goal model state")
        ax.set_yticks(range(smoothed.shape[1]))

    return [features, states]


def _force_panel(ax, demo) -> None:
    ax.step(demo.times - demo.times[0], demo.peak_force, where="pre")
    ax.set_ylabel("peak contact\nforce [N]")


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
margin:.4em;font-size:.85em;vertical-align:top}figure img{width:300px;border:1px solid #999;
image-rendering:pixelated}.warn{color:#a00}"""

_LEGEND = ("Segment drawn over the object camera's crop: <span style='color:#0a0'>kept</span>, "
           "<span style='color:#d00'>object-coloured but dropped</span>, "
           "<span style='color:#05f'>object (in a schema-2 file's stored frames: of the object's hue) but not "
           "object-coloured</span>.")


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
                 "recorded without the camera, a schema-1 robot demonstration or a scenario without the camera)</p>",
                 _demo_figure(skill, demo, track)]
    page = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>fit of {html.escape(skill.name)}</title>"
            f"<style>{_STYLE}</style></head><body>{''.join(body)}</body></html>\n")
    return atomic_write_text(path, page)


def _demo_name(demo, i: int) -> str:
    return Path(demo.path).stem if demo.path else f"demo_{i:03d}"
