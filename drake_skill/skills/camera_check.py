"""Does the segment hold the whole object? ``drake-skill skills FILE --check-camera``.

Before anyone records demonstrations of a skill, its scenario's camera and the
segmenter's thresholds (docs/method.md section 3) must keep the whole object in
the segment at every state of its joint: a part the segment loses is a part
the goal model never sees (a reward that learns "part missing" as the goal).

:func:`check_camera` builds the scenario's simulated station once, then for
each of ``n_poses`` object poses (``station.random_object_pose(seed + k)``,
within the scenario's randomisation, the poses that demonstrations with seeds
``seed..seed + n_poses - 1`` use) and each of ``n_joints`` joint positions
evenly spread between the object's joint limits, sets the plant's positions
directly (no simulation; the robot at ``q_home``), renders the object camera
(the crop the ``ObjectSegmenter`` reads) and segments it with the station's
segmenter settings (:func:`~drake_skill.perception.systems.segmenter_config_for_station`),
the table plane fitted once per pose on the full frame, as the segmenter does
at a run's first frame.

Ground truth is the renderer's label image: the object's visible pixels are
those whose label is one of the object model instance's perception geometries'
labels. Per frame the *kept fraction* is the share of those pixels that the
segment holds (pixels the segment holds beyond the object are reported as
``extra``). No visible object pixel in a frame is an error naming the frame
and the fix: the camera does not see the object there.
"""

from __future__ import annotations

import dataclasses as dc
import math

import numpy as np

__all__ = ["CameraCheck", "FrameCheck", "check_camera", "fit_plane", "frame_pixels", "object_labels", "object_truth"]


@dc.dataclass
class FrameCheck:
    """One rendered frame: object pose ``[x, y, yaw]`` [m, m, rad], joint [rad or m], the
    object's visible pixels, the segment's pixels on the object and beyond it, kept fraction."""

    pose: list[float]
    joint: float
    visible: int
    kept: int
    extra: int

    @property
    def kept_fraction(self) -> float:
        return self.kept / self.visible


@dc.dataclass
class CameraCheck:
    """The check of one skill: every frame and the worst one."""

    skill: str
    frames: list[FrameCheck]

    @property
    def worst(self) -> FrameCheck:
        """The frame with the least kept fraction (the first of ties)."""
        return min(self.frames, key=lambda f: f.kept_fraction)

    def summary(self) -> dict:
        """``{"skill", "kept_fraction_min", "at_joint", "at_pose": [x, y, yaw], "frames"}``."""
        w = self.worst
        return {"skill": self.skill, "kept_fraction_min": round(w.kept_fraction, 4),
                "at_joint": round(w.joint, 4), "at_pose": [round(v, 4) for v in w.pose],
                "frames": len(self.frames)}


def object_labels(station) -> np.ndarray:
    """Render labels (int) of the perception geometries of the station's object model instance."""
    from pydrake.geometry import Role

    plant, inspector = station.plant, station.scene_graph.model_inspector()
    labels = set()
    for body_index in plant.GetBodyIndices(station.object_instance):
        frame_id = plant.GetBodyFrameIdIfExists(body_index)
        if frame_id is None:
            continue
        for g in inspector.GetGeometries(frame_id, Role.kPerception):
            props = inspector.GetPerceptionProperties(g)
            if props is not None and props.HasProperty("label", "id"):
                labels.add(int(props.GetProperty("label", "id")))
    return np.array(sorted(labels), dtype=np.int64)


def object_truth(station, context, labels) -> np.ndarray:
    """(H, W) bool: the object camera's pixels whose render label is one of ``labels`` (``object_labels``)."""
    return np.isin(station.GetOutputPort("object_label_image").Eval(context).data[:, :, 0], labels)


def _joint_values(station, n_joints: int) -> np.ndarray:
    joint = station.object_joint
    lo, hi = float(joint.position_lower_limits()[0]), float(joint.position_upper_limits()[0])
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise ValueError(f"object joint '{joint.name()}' has an unbounded range [{lo}, {hi}]; "
                         "give it <limit> lower and upper in the object's model")
    return np.linspace(lo, hi, n_joints)


def _pose_vector(X_WO) -> list[float]:
    p = X_WO.translation()
    return [float(p[0]), float(p[1]), float(X_WO.rotation().ToRollPitchYaw().yaw_angle())]


def frame_pixels(station, context, seg_config, plane):
    """The object camera's crop at ``context`` as the segmenter sees it: colour image, object-coloured
    pixels and the segment's pixels (a :class:`~drake_skill.perception.segmentation.SegmentPixels`)."""
    from drake_skill.perception.segmentation import segment_object, segment_pixels

    cloud = station.GetOutputPort("object_point_cloud").Eval(context)
    shape = station.object_camera.window.shape
    xyz, rgb = cloud.xyzs().T, cloud.rgbs().T
    return segment_pixels(rgb, seg_config, shape, segment_object(xyz, rgb, plane, seg_config, shape))


def fit_plane(station, context, seg_config, seed: int) -> np.ndarray:
    """The table plane from the full frame at ``context``, as the segmenter fits it on a run's first frame."""
    from drake_skill.perception.segmentation import fit_table_plane

    cam = station.config.camera
    cloud = station.GetOutputPort("point_cloud").Eval(context)
    return fit_table_plane(cloud.xyzs().T, seg_config, (cam.height, cam.width), seed=seed)


def check_camera(station_config, skill_name: str, n_joints: int = 7, n_poses: int = 3,
                 seed: int = 0) -> CameraCheck:
    """Renders ``n_poses`` x ``n_joints`` frames of ``station_config``'s object and compares each
    segment with the label image (module docstring). Raises ValueError when the station has
    no camera or the camera sees none of the object in some frame."""
    from drake_skill.perception.systems import segmenter_config_for_station
    from drake_skill.station.make import make_station

    if n_joints < 1 or n_poses < 1:
        raise ValueError(f"--joints/--poses: expected at least 1 each, got {n_joints}, {n_poses}")
    if not station_config.enable_camera:
        raise ValueError("the scenario has enable_camera: false; the camera check needs the camera")
    station = make_station(station_config)
    seg_config = segmenter_config_for_station(station_config, station.object_camera.window)
    labels = object_labels(station)
    context = station.CreateDefaultContext()
    frames = []
    for k in range(n_poses):
        X_WO = station.random_object_pose(seed + k)
        station.set_object_pose(context, X_WO)
        station.set_object_joint(context, station_config.object.initial_joint)
        plane = fit_plane(station, context, seg_config.segmentation, seed)
        for q in _joint_values(station, n_joints):
            station.set_object_joint(context, q)
            frames.append(_check_frame(station, context, seg_config.segmentation, plane, labels,
                                       _pose_vector(X_WO), float(q)))
    return CameraCheck(skill_name, frames)


def _check_frame(station, context, seg_config, plane, labels, pose, q) -> FrameCheck:
    truth = object_truth(station, context, labels)
    visible = int(truth.sum())
    if visible == 0:
        x, y, yaw = pose
        raise ValueError(f"the camera sees none of the object '{station.config.object.model}' at joint {q:.3g}, "
                         f"pose x {x:.3f} m, y {y:.3f} m, yaw {yaw:.3f} rad; aim the camera at the object "
                         "(the scenario's camera: X_PB) or place the object in its view (object.x/y)")
    mask = frame_pixels(station, context, seg_config, plane).kept
    return FrameCheck(pose, q, visible, int((mask & truth).sum()), int((mask & ~truth).sum()))


def table(check: CameraCheck) -> str:
    """A short table: per joint value, the least kept fraction over the poses and where."""
    rows = [("joint", "visible px", "kept", "extra px", "worst pose [x, y, yaw]")]
    for q in sorted({f.joint for f in check.frames}):
        w = min((f for f in check.frames if f.joint == q), key=lambda f: f.kept_fraction)
        rows.append((f"{q:.3f}", str(w.visible), f"{w.kept_fraction:.3f}", str(w.extra),
                     "[" + ", ".join(f"{v:.3f}" for v in w.pose) + "]"))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(v.ljust(n) for v, n in zip(r, widths)).rstrip() for r in rows]
    s = check.summary()
    lines.append(f"{check.skill}: the segment keeps at least {s['kept_fraction_min']:.3f} of the object's visible "
                 f"pixels ({s['frames']} frames; least at joint {s['at_joint']:g}, pose {s['at_pose']})")
    return "\n".join(lines)
