"""The object camera: the Kinect's view cropped to where the object can appear.

The perception chain (docs/architecture.md: camera -> ObjectSegmenter ->
PcaeFeaturizer -> PomrpReward) only needs the pixels that can show the
object. :func:`add_object_camera` adds, next to the full-frame camera, a second
``RgbdSensor`` at the same pose whose intrinsics are the *crop* of the full
camera's: the same focal lengths and pixel grid, the principal point shifted
by the crop's corner,

    fx' = fx,  fy' = fy,  cx' = cx - x0,  cy' = cy - y0,   width' = w, height' = h,

so pixel (u', v') of the object camera is pixel (x0 + u', y0 + v') of the full
frame (a pinhole ``u = fx X / Z + cx``: shifting the principal point only
shifts the pixel indices). Its images and its organised point cloud are
therefore the matching crop of the full-frame ones (up to rounding, below), at
a fraction of the rendering and cloud cost. The full-frame camera stays for
pictures, Meshcat and the demonstration images.

**Colour** (:class:`CroppedColorCamera`). RenderEngineVtk ends its colour pass
with FXAA, a screen-space anti-aliasing filter: an output pixel reads the
rendered pixels up to ``n`` = 12 along an edge through it (VTK's endpoint
search, ``EndpointSearchIterations``) and one across it, clamped at the
image's border. A crop rendered to its own border would differ from the full
frame wherever an edge crosses that border. The colour image is therefore
rendered :data:`FXAA_REACH_PX` = ``n`` pixels beyond the window on every side
where the full image extends (the crop intrinsics above of the grown window
``x0 - l, y0 - t, w + l + r, h + t + b``, each margin ``min(n, pixels to the
image's border)``) and cut back to the window; every pixel of the window
then reads the same pixel positions as in the full frame. Depth and labels
have no such pass and are rendered at the window. What remains is rounding:
the two frusta's projection matrices differ, and the float transform of a
vertex rounds differently in each, so a pixel whose centre lies within
rounding of an edge may be covered in one and not the other, and where two
faces coincide the depth test between them may go either way; FXAA then
carries such a pixel along its edge.

The window (:class:`CropWindow`) is sized once, at build time, from the
object's swept volume: :func:`object_swept_points` places the corners of the
oriented bounding box of every perception geometry of the object's bodies
(``pydrake.geometry.CalcObb``) at every combination of

- the articulated joint over its whole range (lid angle / drawer travel,
  ``n_joint`` samples between the joint's limits),
- the base pose over the randomisation of ``ObjectConfig``: x and y at the
  ends and the centre of ``+-randomize_xy``, yaw at ``n_yaw`` values in
  ``+-randomize_yaw`` around the nominal pose;

:func:`crop_window` projects them and takes their bounding rectangle plus
``margin_px`` pixels (covering the sampling of the yaw and joint and the
rasteriser's edge pixels), clipped to the image and grown, where needed, to
hold the principal point (Drake's ``CameraInfo`` requires it inside the
image). (The projection of a corner
is a linear-fractional function of the base translation, extreme at the
ends of the translation ranges; yaw and joint are sampled finely enough
that the margin covers what lies between samples.)

**The render scene** (:func:`add_render_scene`). A renderer registered with
the plant's own SceneGraph is sent every geometry's pose at every plant step
(SceneGraph updates its render engines whenever the contact query updates
the poses), although the cameras render at 10 Hz. The cameras therefore
render a second SceneGraph holding only the perception geometry: each of the
plant's perception geometries is registered there again (same shape, pose in
its body frame and perception properties, hence the same colours and
labels), on one frame per body, and a small system turns the plant's body
poses into that scene's frame poses. It is evaluated only when a camera
renders, so the plant's steps carry no rendering cost; the images are those
of the plant's scene.

Ports the station exports from this camera (rendered on demand, like the
full-frame ones): ``object_point_cloud`` (PointCloud, world frame, xyz + rgb,
organised ``height' x width'``; rgb from the colour image), ``object_color_image``
(:class:`CroppedColorCamera`), ``object_depth_image`` (32F, m) and
``object_label_image`` (ground truth for tests; never rendered unless
evaluated), the last two from the ``RgbdSensor``.
"""

from __future__ import annotations

import dataclasses as dc
import math

import numpy as np
from pydrake.common.value import AbstractValue, Value
from pydrake.geometry import (
    CalcObb,
    ColorRenderCamera,
    DepthRenderCamera,
    FramePoseVector,
    GeometryFrame,
    GeometryInstance,
    QueryObject,
    RenderCameraCore,
    Role,
    SceneGraph,
)
from pydrake.systems.framework import LeafSystem
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.tree import BodyIndex
from pydrake.perception import BaseField, DepthImageToPointCloud
from pydrake.systems.primitives import ConstantValueSource
from pydrake.systems.sensors import CameraInfo, ImageRgba8U, PixelType, RgbdSensor

__all__ = ["CropWindow", "CroppedColorCamera", "ObjectCamera", "add_object_camera", "add_render_scene",
           "color_padding", "crop_camera_info", "crop_window", "export_camera_ports", "object_swept_points"]

MARGIN_PX = 6
"""Pixels added on every side of the swept volume's projection."""

FXAA_REACH_PX = 12
"""Pixels the object camera's colour image is rendered beyond its window on every side
(where the full image has them): the reach of RenderEngineVtk's FXAA pass along an edge
(module docstring)."""


@dc.dataclass(frozen=True)
class CropWindow:
    """A rectangle of the full frame: columns ``x0 .. x0 + width - 1``, rows ``y0 .. y0 + height - 1``."""

    x0: int
    y0: int
    width: int
    height: int

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width), the organised cloud's image shape."""
        return (self.height, self.width)

    def slices(self) -> tuple[slice, slice]:
        """(rows, columns) of the full frame: ``full_image[window.slices()]`` is the crop."""
        return slice(self.y0, self.y0 + self.height), slice(self.x0, self.x0 + self.width)

    def crop(self, image: np.ndarray) -> np.ndarray:
        """The crop of a full-frame array (H, W, ...) (a view)."""
        return np.asarray(image)[self.slices()]


@dc.dataclass(frozen=True)
class ObjectCamera:
    """What :func:`add_object_camera` built: the window, its intrinsics, the sensor and the port names."""

    window: CropWindow
    info: CameraInfo
    sensor: RgbdSensor
    image_port_names: tuple[str, str] = ("object_color_image", "object_depth_image")
    cloud_port_name: str = "object_point_cloud"
    label_port_name: str = "object_label_image"
    color_padding: tuple[int, int, int, int] = (0, 0, 0, 0)
    """Pixels (left, top, right, bottom) the colour image is rendered beyond the window."""


class _RenderPoses(LeafSystem):
    """Output ``frame_poses`` (FramePoseVector of the render scene's frames): the
    plant's body poses X_WB (input ``body_poses``) of the bodies the frames stand for."""

    def __init__(self, frames: list[tuple[object, int]]):
        super().__init__()
        self._frames = frames                       # (render-scene FrameId, body index)
        self._poses = self.DeclareAbstractInputPort("body_poses", Value([RigidTransform()]))
        self.DeclareAbstractOutputPort("frame_poses", lambda: Value(FramePoseVector()), self._calc,
                                       {self.all_input_ports_ticket()})

    def _calc(self, context, output):
        X_WB = self._poses.Eval(context)
        poses = output.get_mutable_value()
        poses.clear()
        for frame_id, body in self._frames:
            poses.set_value(frame_id, X_WB[body])


def add_render_scene(builder, station, renderer_name: str, render_engine) -> SceneGraph:
    """Adds the render scene (see the module docstring) of ``station``'s plant, with
    ``render_engine`` registered as ``renderer_name``; returns its SceneGraph, whose
    query port the cameras read. Call after the plant is finalised."""
    plant, inspector = station.plant, station.scene_graph.model_inspector()
    scene = builder.AddNamedSystem("render_scene", SceneGraph())
    scene.AddRenderer(renderer_name, render_engine)
    source = scene.RegisterSource("station_perception_geometry")
    world = plant.GetBodyFrameIdOrThrow(plant.world_body().index())
    frames = []
    for i in range(plant.num_bodies()):
        body = plant.get_body(BodyIndex(i))
        plant_frame = plant.GetBodyFrameIdIfExists(body.index())
        if plant_frame is None:
            continue
        geometries = inspector.GetGeometries(plant_frame, Role.kPerception)
        if not geometries:
            continue
        frame = None
        if plant_frame != world:
            frame = scene.RegisterFrame(source, GeometryFrame(f"{body.name()}_{i}"))
            frames.append((frame, i))
        for g in geometries:
            instance = GeometryInstance(inspector.GetPoseInFrame(g), inspector.GetShape(g), inspector.GetName(g))
            instance.set_perception_properties(inspector.GetPerceptionProperties(g))
            if frame is None:
                scene.RegisterAnchoredGeometry(source, instance)
            else:
                scene.RegisterGeometry(source, frame, instance)
    poses = builder.AddNamedSystem("render_scene_poses", _RenderPoses(frames))
    builder.Connect(plant.get_body_poses_output_port(), poses.get_input_port())
    builder.Connect(poses.get_output_port(), scene.get_source_pose_port(source))
    return scene


def crop_camera_info(info: CameraInfo, window: CropWindow) -> CameraInfo:
    """Intrinsics of the crop ``window`` of a camera ``info``: same focal lengths, principal
    point shifted by the window's corner (see the module docstring)."""
    if not (0 <= window.x0 and 0 <= window.y0 and window.width >= 1 and window.height >= 1
            and window.x0 + window.width <= info.width() and window.y0 + window.height <= info.height()):
        raise ValueError(f"crop window {window} does not lie inside the {info.width()} x {info.height()} image")
    return CameraInfo(window.width, window.height, info.focal_x(), info.focal_y(),
                      info.center_x() - window.x0, info.center_y() - window.y0)


def _obb_corners(shape, X_BG: RigidTransform) -> np.ndarray:
    """The 8 corners (8, 3) of a shape's oriented bounding box, in its body's frame B."""
    obb = CalcObb(shape)
    if obb is None:     # half-spaces have none: they cannot be bounded
        raise ValueError(f"object geometry of shape {type(shape).__name__} has no bounding box; "
                         "the object camera needs bounded geometry")
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
    local = signs * obb.half_width()
    X_BO = X_BG @ obb.pose()
    return (X_BO.rotation().matrix() @ local.T).T + X_BO.translation()


def object_swept_points(station, n_joint: int = 45, n_yaw: int = 5) -> np.ndarray:
    """World points (M, 3) [m] bounding every place the object's perception geometry can take
    (see the module docstring). ``station`` is a :class:`~drake_skill.station.sim.builder.Station`
    under construction (its plant finalised)."""
    plant, inspector = station.plant, station.scene_graph.model_inspector()
    obj, joint, o = station.object_instance, station.object_joint, station.config.object
    corners = {}
    for body_index in plant.GetBodyIndices(obj):
        body = plant.get_body(body_index)
        frame_id = plant.GetBodyFrameIdIfExists(body_index)
        if frame_id is None:
            continue
        pts = [_obb_corners(inspector.GetShape(g), inspector.GetPoseInFrame(g))
               for g in inspector.GetGeometries(frame_id, Role.kPerception)]
        if pts:
            corners[body_index] = (body, np.concatenate(pts))
    if not corners:
        raise ValueError("the object has no perception geometry: nothing for the object camera to see")
    lo, hi = float(joint.position_lower_limits()[0]), float(joint.position_upper_limits()[0])
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise ValueError(f"object joint '{joint.name()}' has an unbounded range [{lo}, {hi}]; "
                         "the object camera needs joint limits")
    context = plant.CreateDefaultContext()
    out = []
    for dx in (-o.randomize_xy, 0.0, o.randomize_xy):
        for dy in (-o.randomize_xy, 0.0, o.randomize_xy):
            for dyaw in np.linspace(-o.randomize_yaw, o.randomize_yaw, n_yaw):
                X_WO = RigidTransform(RollPitchYaw(0.0, 0.0, o.yaw + dyaw), [o.x + dx, o.y + dy, 0.0])
                plant.SetFreeBodyPose(context, station.object_base, X_WO)
                for q in np.linspace(lo, hi, n_joint):
                    positions = plant.GetPositions(context).copy()
                    positions[joint.position_start()] = q
                    plant.SetPositions(context, positions)
                    for body, pts in corners.values():
                        X_WB = plant.EvalBodyPoseInWorld(context, body)
                        out.append((X_WB.rotation().matrix() @ pts.T).T + X_WB.translation())
    return np.concatenate(out)


def crop_window(points_W: np.ndarray, X_WC: RigidTransform, info: CameraInfo,
                margin_px: int = MARGIN_PX) -> CropWindow:
    """The smallest window of the image ``info`` holding the projections of ``points_W``
    (M, 3) [m, world] seen from ``X_WC`` (Drake camera frame: z forward, x right, y down),
    grown by ``margin_px`` and clipped to the image."""
    p_C = X_WC.inverse().multiply(np.asarray(points_W, float).T)       # (3, M)
    if np.any(p_C[2] <= 1e-6):
        raise ValueError("part of the object's swept volume lies behind the camera; "
                         "aim the camera at the object (camera.position / camera.target)")
    u = info.focal_x() * p_C[0] / p_C[2] + info.center_x()
    v = info.focal_y() * p_C[1] / p_C[2] + info.center_y()
    # Drake's CameraInfo needs the principal point inside the image: the window
    # always holds the pixel around it.
    cx, cy = info.center_x(), info.center_y()
    x0 = max(0, min(int(math.floor(u.min())) - margin_px, int(math.floor(cx))))
    y0 = max(0, min(int(math.floor(v.min())) - margin_px, int(math.floor(cy))))
    x1 = min(info.width(), max(int(math.ceil(u.max())) + 1 + margin_px, int(math.floor(cx)) + 2))
    y1 = min(info.height(), max(int(math.ceil(v.max())) + 1 + margin_px, int(math.floor(cy)) + 2))
    if x1 <= x0 or y1 <= y0:
        raise ValueError("the object's swept volume projects outside the camera image; "
                         "aim the camera at the object (camera.position / camera.target)")
    return CropWindow(x0, y0, x1 - x0, y1 - y0)


def color_padding(info: CameraInfo, window: CropWindow, reach_px: int = FXAA_REACH_PX) -> tuple[int, int, int, int]:
    """Pixels (left, top, right, bottom) to render beyond ``window`` of the image ``info``:
    ``reach_px`` on every side, clipped to the image."""
    return (min(reach_px, window.x0), min(reach_px, window.y0),
            min(reach_px, info.width() - window.x0 - window.width),
            min(reach_px, info.height() - window.y0 - window.height))


class CroppedColorCamera(LeafSystem):
    """The colour image of the crop ``window`` of ``color_camera`` (its body at ``X_PB`` in
    the frame ``parent_id``), rendered ``reach_px`` pixels beyond the window on every side
    the full image extends to (:func:`color_padding`) and cut back to the window (see the
    module docstring). Input ``query`` (QueryObject); output ``color_image``
    (ImageRgba8U, ``window.width x window.height``), rendered when evaluated."""

    def __init__(self, color_camera: ColorRenderCamera, window: CropWindow, parent_id, X_PB: RigidTransform,
                 reach_px: int = FXAA_REACH_PX):
        super().__init__()
        full, core = color_camera.core().intrinsics(), color_camera.core()
        crop_camera_info(full, window)          # checks that the window lies inside the image
        self.padding = left, top, right, bottom = color_padding(full, window, reach_px)
        padded = crop_camera_info(full, CropWindow(window.x0 - left, window.y0 - top, window.width + left + right,
                                                   window.height + top + bottom))
        self._camera = ColorRenderCamera(RenderCameraCore(core.renderer_name(), padded, core.clipping(),
                                                          core.sensor_pose_in_camera_body()), show_window=False)
        self._parent, self._X_PB = parent_id, X_PB
        self._rows, self._cols = slice(top, top + window.height), slice(left, left + window.width)
        self._query = self.DeclareAbstractInputPort("query", Value(QueryObject()))
        self.DeclareAbstractOutputPort("color_image", lambda: Value(ImageRgba8U(window.width, window.height)),
                                       self._calc, {self._query.ticket()})

    def _calc(self, context, output):
        image = self._query.Eval(context).RenderColorImage(self._camera, self._parent, self._X_PB)
        output.get_mutable_value().mutable_data[:] = image.data[self._rows, self._cols]


def export_camera_ports(builder, info: CameraInfo, X_WC: RigidTransform, color, depth, label,
                        prefix: str = "") -> None:
    """Exports a camera's ``{prefix}color_image``, ``{prefix}depth_image`` (32F, m) and
    ``{prefix}label_image`` (output ports ``color``, ``depth``, ``label``) and their world-frame
    cloud ``{prefix}point_cloud`` (xyz + rgb): Drake's ``DepthImageToPointCloud`` with the camera
    pose X_WC from a constant source, so the cloud's cache does not depend on the robot's state.
    The simulated and the hardware station wire their full frame and their object crop with it."""
    to_cloud = builder.AddNamedSystem(f"{prefix}depth_to_cloud", DepthImageToPointCloud(
        info, PixelType.kDepth32F, 1.0, BaseField.kXYZs | BaseField.kRGBs))
    builder.Connect(depth, to_cloud.depth_image_input_port())
    builder.Connect(color, to_cloud.color_image_input_port())
    pose = builder.AddNamedSystem(f"{prefix}camera_pose", ConstantValueSource(AbstractValue.Make(X_WC)))
    builder.Connect(pose.get_output_port(), to_cloud.camera_pose_input_port())
    builder.ExportOutput(to_cloud.point_cloud_output_port(), f"{prefix}point_cloud")
    for name, port in (("color_image", color), ("depth_image", depth), ("label_image", label)):
        builder.ExportOutput(port, f"{prefix}{name}")


def add_object_camera(builder, station, color_camera: ColorRenderCamera, depth_camera: DepthRenderCamera,
                      parent_id, X_PC: RigidTransform, margin_px: int = MARGIN_PX) -> ObjectCamera:
    """Adds the object camera next to the full-frame camera described by ``color_camera`` /
    ``depth_camera`` (same renderer, clipping and depth range) mounted at ``X_PC`` on the
    frame ``parent_id``; exports its ports (module docstring) from ``builder``.

    ``station`` is the Station being built (its plant finalised): the window comes
    from its object and ``station.config.object``; the camera must be fixed in the
    world (``parent_id`` the world frame), as the window is computed once. It
    renders ``station.render_scene`` (:func:`add_render_scene`).
    """
    full = color_camera.core().intrinsics()
    world_id = station.plant.GetBodyFrameIdOrThrow(station.plant.world_body().index())
    if parent_id != world_id:
        raise ValueError("the object camera is sized once at build time: mount the camera on the world frame")
    X_WC = X_PC @ color_camera.core().sensor_pose_in_camera_body()
    window = crop_window(object_swept_points(station), X_WC, full, margin_px)
    info = crop_camera_info(full, window)
    core = color_camera.core()
    crop_core = RenderCameraCore(core.renderer_name(), info, core.clipping(), core.sensor_pose_in_camera_body())
    color = ColorRenderCamera(crop_core, show_window=False)
    depth = DepthRenderCamera(RenderCameraCore(depth_camera.core().renderer_name(), info,
                                               depth_camera.core().clipping(),
                                               depth_camera.core().sensor_pose_in_camera_body()),
                              depth_camera.depth_range())
    # Depth and labels: the sensor (its colour port stays unused).
    sensor = builder.AddNamedSystem("object_camera", RgbdSensor(parent_id, X_PC, color, depth))
    scene = station.render_scene
    builder.Connect(scene.get_query_output_port(), sensor.query_object_input_port())
    # Colour: rendered beyond the window and cut back to it (module docstring).
    color_image = builder.AddNamedSystem("object_color_camera",
                                         CroppedColorCamera(color_camera, window, parent_id, X_PC))
    builder.Connect(scene.get_query_output_port(), color_image.get_input_port())
    export_camera_ports(builder, info, X_WC, color_image.get_output_port(), sensor.depth_image_32F_output_port(),
                        sensor.label_image_output_port(), prefix="object_")
    return ObjectCamera(window, info, sensor, color_padding=color_image.padding)
