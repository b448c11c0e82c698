"""Procedural shapes seen as partial single-view depth clouds: PCAE training data.

docs/method.md section 3 (the thesis trained its PCAE on ShapeNet, thesis 3.5 and
6.4; ShapeNet cannot be downloaded here, so the project generates its own
skill-agnostic data). No Drake is imported.

Pipeline for one sample (all lengths in metres, world frame W: z up, table top
at z = 0, object resting on it near the origin):

1. :func:`random_shape` draws one of :data:`SHAPE_KINDS` (boxes, cylinders,
   spheres/ellipsoids, cones, composites, boxes with a lid at any angle,
   drawers at any travel, thin and flat objects, open trays, tori) as a
   triangle mesh ``(V (n, 3) float, F (m, 3) int)``, with a random yaw.
2. :func:`random_camera_pose` puts a pinhole camera like a Kinect v1
   (:class:`DepthCameraConfig`: 640 x 480, 57 deg horizontal FOV) on the upper
   hemisphere, 1-2 m from the object, 20-65 deg elevation, looking at it.
   ``X_WC`` uses the camera convention x right, y down, z forward.
3. :func:`render_depth_points` casts one ray per pixel of the object's image
   footprint with open3d's ``RaycastingScene`` (z-buffer self-occlusion), then
   applies a depth-sensor model: missing returns at grazing incidence,
   random dropouts, depth-dependent axial noise (Nguyen et al. 2012:
   sigma_z = 1.2 mm + 1.9 mm/m^2 (z - 0.4 m)^2), lateral pixel jitter and
   disparity quantisation (1/8 px steps, baseline 7.5 cm). Points are returned
   in W.
4. Optionally, points near the table (z below a few mm, as a table-plane
   removal would cut them) are dropped, and :func:`drake_skill.perception.segmentation.resample_points`
   brings the cloud to exactly 2048 points (with replacement if fewer).

:func:`generate_clouds` is seeded per sample (``np.random.default_rng([seed, i])``),
so a dataset is reproducible and any slice can be generated alone.
"""


import math
from dataclasses import dataclass, field

import numpy as np

from drake_skill.common import N_POINTS, look_at
from drake_skill.perception.segmentation import resample_points

SHAPE_KINDS = (
    "box",
    "cylinder",
    "ellipsoid",
    "cone",
    "composite",
    "lidded_box",
    "drawer",
    "thin",
    "tray",
    "torus",
)
"""Shape families drawn by :func:`random_shape`."""

SHAPE_WEIGHTS = (0.10, 0.10, 0.07, 0.07, 0.14, 0.18, 0.14, 0.10, 0.05, 0.05)
"""Probabilities of :data:`SHAPE_KINDS` (lidded boxes and drawers oversampled)."""


@dataclass
class DepthCameraConfig:
    """Pinhole depth camera and its noise model (defaults: Kinect v1)."""

    width: int = 640
    height: int = 480
    fov_x_deg: float = 57.0
    """Horizontal field of view; the focal length follows, square pixels."""
    max_incidence_deg: float = 82.0
    """Rays hitting a surface at more than this angle from its normal return nothing."""
    grazing_start_deg: float = 65.0
    """From here to ``max_incidence_deg`` the chance of a missing return rises linearly to 1."""
    dropout: float = 0.02
    """Probability that any pixel returns nothing."""
    axial_noise_m: list[float] = field(default_factory=lambda: [0.0012, 0.0019, 0.4])
    """sigma_z = a + b (z - c)^2 (m), Nguyen et al. 2012."""
    lateral_noise_px: float = 0.3
    """Std of the pixel jitter applied before back-projection."""
    baseline_m: float = 0.075
    """Projector-camera baseline for disparity quantisation."""
    disparity_step_px: float = 0.125
    """Disparity quantisation step (0 disables quantisation)."""
    min_range_m: float = 0.5
    max_range_m: float = 4.0

    @property
    def focal_px(self) -> float:
        return 0.5 * self.width / math.tan(math.radians(0.5 * self.fov_x_deg))


@dataclass
class ViewConfig:
    """Where :func:`random_camera_pose` puts the camera."""

    distance_m: list[float] = field(default_factory=lambda: [1.0, 2.0])
    elevation_deg: list[float] = field(default_factory=lambda: [20.0, 65.0])
    look_at_jitter_m: float = 0.03
    roll_deg: float = 3.0


@dataclass
class CloudConfig:
    """One training cloud: camera, viewpoint, post-processing."""

    camera: DepthCameraConfig = field(default_factory=DepthCameraConfig)
    view: ViewConfig = field(default_factory=ViewConfig)
    n_points: int = N_POINTS
    table_cut_probability: float = 0.5
    """Chance that points below a random height in [0, table_cut_max_m] are removed."""
    table_cut_max_m: float = 0.012
    min_points: int = 64
    """Views with fewer surviving points are redrawn."""


# --------------------------------------------------------------------------- meshes

Mesh = tuple[np.ndarray, np.ndarray]


def _rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


_UNIT_CACHE: dict[str, Mesh] = {}


def _unit(kind: str) -> Mesh:
    """Unit primitives centred at the origin: box 1x1x1, cylinder r=0.5 h=1 along z, sphere r=0.5,
    cone r=0.5 h=1 (base z=-0.5)."""
    if kind not in _UNIT_CACHE:
        import open3d as o3d

        g = o3d.geometry.TriangleMesh
        if kind == "box":
            m = g.create_box(1.0, 1.0, 1.0)
            shift = np.array([0.5, 0.5, 0.5])
        elif kind == "cylinder":
            m = g.create_cylinder(radius=0.5, height=1.0, resolution=32, split=1)
            shift = np.zeros(3)
        elif kind == "sphere":
            m = g.create_sphere(radius=0.5, resolution=16)
            shift = np.zeros(3)
        elif kind == "cone":
            m = g.create_cone(radius=0.5, height=1.0, resolution=32, split=1)
            shift = np.array([0.0, 0.0, 0.5])
        else:
            raise ValueError(f"kind: unknown unit primitive '{kind}'")
        v = np.asarray(m.vertices, dtype=np.float64) - shift
        f = np.asarray(m.triangles, dtype=np.int64)
        _UNIT_CACHE[kind] = (v, f)
    return _UNIT_CACHE[kind]


def primitive(kind: str, size, center=(0.0, 0.0, 0.0), R: np.ndarray | None = None) -> Mesh:
    """A primitive scaled by ``size`` (3,) (full extents along its own x, y, z), rotated by R, moved to ``center``."""
    v, f = _unit(kind)
    v = v * np.asarray(size, dtype=np.float64)
    if R is not None:
        v = v @ np.asarray(R).T
    return v + np.asarray(center, dtype=np.float64), f


def torus(radius: float, tube: float, center=(0.0, 0.0, 0.0), R: np.ndarray | None = None) -> Mesh:
    """A torus around its z axis (ring radius, tube radius in m)."""
    import open3d as o3d

    m = o3d.geometry.TriangleMesh.create_torus(torus_radius=radius, tube_radius=tube,
                                               radial_resolution=24, tubular_resolution=12)
    v = np.asarray(m.vertices, dtype=np.float64)
    if R is not None:
        v = v @ np.asarray(R).T
    return v + np.asarray(center, dtype=np.float64), np.asarray(m.triangles, dtype=np.int64)


def merge(*meshes: Mesh) -> Mesh:
    """Concatenates meshes (no boolean union; overlapping parts are fine for ray casting)."""
    vs, fs, off = [], [], 0
    for v, f in meshes:
        vs.append(v)
        fs.append(f + off)
        off += len(v)
    return np.concatenate(vs), np.concatenate(fs)


def transform(mesh: Mesh, R: np.ndarray, p=(0.0, 0.0, 0.0)) -> Mesh:
    v, f = mesh
    return v @ np.asarray(R).T + np.asarray(p), f


def rest_on_table(mesh: Mesh) -> Mesh:
    """Shifts the mesh so its lowest vertex is at z = 0 and its xy box is centred on the origin."""
    v, f = mesh
    lo, hi = v.min(axis=0), v.max(axis=0)
    shift = np.array([-(lo[0] + hi[0]) / 2, -(lo[1] + hi[1]) / 2, -lo[2]])
    return v + shift, f


def lidded_box(size=(0.20, 0.30, 0.15), lid_angle_rad: float = 0.0, lid_thickness: float = 0.012) -> Mesh:
    """A solid box with a lid hinged along its back top edge, resting on z = 0.

    size: (depth x, width y, total height z) in m, closed. The front faces +x;
    the hinge is the line x = -depth/2, z = height - lid_thickness. The lid
    turns about it by ``lid_angle_rad`` (0 closed, pi/2 upright, rad).
    """
    d, w, h = (float(s) for s in size)
    hb = h - lid_thickness
    body = primitive("box", (d, w, hb), (0.0, 0.0, hb / 2))
    lid = primitive("box", (d, w, lid_thickness), (d / 2, 0.0, lid_thickness / 2))  # hinge at lid's own origin
    lid = transform(lid, _rot_y(-lid_angle_rad), (-d / 2, 0.0, hb))
    return merge(body, lid)


def drawer(size=(0.30, 0.35, 0.20), travel: float = 0.0, rng: np.random.Generator | None = None) -> Mesh:
    """A cabinet with one open-top drawer pulled out by ``travel`` m along +x, resting on z = 0.

    size: (depth x, width y, height z) of the cabinet in m.
    """
    d, w, h = (float(s) for s in size)
    rng = rng or np.random.default_rng(0)
    wall = 0.012
    dh = h * rng.uniform(0.35, 0.8)  # drawer front height
    top = h - rng.uniform(0.01, 0.04)
    z0 = top - dh
    cab = primitive("box", (d, w, h), (0.0, 0.0, h / 2))
    front_x = d / 2 + travel
    front = primitive("box", (wall, w * 0.94, dh), (front_x + wall / 2, 0.0, z0 + dh / 2))
    handle = primitive("box", (0.02, w * rng.uniform(0.2, 0.5), 0.015), (front_x + wall + 0.01, 0.0, z0 + dh * 0.6))
    td = d * 0.92  # tray depth
    tw = w * 0.88
    th = dh * 0.85
    tx0 = front_x - td  # tray back x
    parts = [cab, front, handle,
             primitive("box", (td, tw, wall), (tx0 + td / 2, 0.0, z0 + wall / 2)),  # bottom
             primitive("box", (td, wall, th), (tx0 + td / 2, tw / 2 - wall / 2, z0 + th / 2)),  # sides
             primitive("box", (td, wall, th), (tx0 + td / 2, -tw / 2 + wall / 2, z0 + th / 2)),
             primitive("box", (wall, tw, th), (tx0 + wall / 2, 0.0, z0 + th / 2))]  # back
    return merge(*parts)


def _tray(rng: np.random.Generator) -> Mesh:
    d, w = rng.uniform(0.08, 0.45, size=2)
    h = rng.uniform(0.03, 0.25)
    t = rng.uniform(0.005, 0.02)
    return merge(
        primitive("box", (d, w, t), (0, 0, t / 2)),
        primitive("box", (t, w, h), (d / 2 - t / 2, 0, h / 2)),
        primitive("box", (t, w, h), (-d / 2 + t / 2, 0, h / 2)),
        primitive("box", (d, t, h), (0, w / 2 - t / 2, h / 2)),
        primitive("box", (d, t, h), (0, -w / 2 + t / 2, h / 2)),
    )


def _random_primitive(rng: np.random.Generator, lo: float = 0.04, hi: float = 0.4) -> Mesh:
    kind = rng.choice(["box", "cylinder", "sphere", "cone"], p=[0.4, 0.3, 0.15, 0.15])
    if kind == "box":
        size = rng.uniform(lo, hi, size=3)
    elif kind == "sphere":
        size = rng.uniform(lo, hi) * rng.uniform(0.7, 1.3, size=3)
    else:
        r = rng.uniform(lo, hi)
        size = (r, r, rng.uniform(lo, hi))
    R = np.eye(3)
    if kind in ("cylinder", "cone") and rng.random() < 0.25:
        R = _rot_x(math.pi / 2)  # lying on its side
    return rest_on_table(primitive(kind, size, R=R))


def _composite(rng: np.random.Generator) -> Mesh:
    base = _random_primitive(rng, 0.08, 0.4)
    parts = [base]
    for _ in range(int(rng.integers(1, 4))):
        v_all = np.concatenate([p[0] for p in parts])
        lo, hi = v_all.min(axis=0), v_all.max(axis=0)
        part = _random_primitive(rng, 0.03, 0.25)
        pv = part[0]
        plo, phi = pv.min(axis=0), pv.max(axis=0)
        if rng.random() < 0.6:  # stacked on top, somewhere over the footprint
            x = rng.uniform(lo[0], hi[0]) * 0.6
            y = rng.uniform(lo[1], hi[1]) * 0.6
            z = hi[2] - rng.uniform(0, 0.3) * (phi[2] - plo[2])
        else:  # beside, touching the side
            ang = rng.uniform(0, 2 * math.pi)
            rad = 0.5 * max(hi[0] - lo[0], hi[1] - lo[1]) + 0.4 * max(phi[0] - plo[0], phi[1] - plo[1])
            x, y = rad * math.cos(ang), rad * math.sin(ang)
            z = rng.uniform(0, 0.5) * (hi[2] - lo[2])
        parts.append(transform(part, _rot_z(rng.uniform(0, 2 * math.pi)), (x, y, z)))
    return merge(*parts)


def random_shape(rng: np.random.Generator, kind: str | None = None) -> tuple[Mesh, dict]:
    """Draws a random object mesh resting on the table near the origin, with random yaw.

    Returns ``((V, F), info)``; ``info`` has ``kind`` and the state parameters
    (``lid_angle_rad``, ``travel_m``) where they apply.
    """
    if kind is None:
        kind = str(rng.choice(SHAPE_KINDS, p=np.asarray(SHAPE_WEIGHTS) / np.sum(SHAPE_WEIGHTS)))
    if kind not in SHAPE_KINDS:
        raise ValueError(f"kind: expected one of {SHAPE_KINDS}, got '{kind}'")
    info: dict = {"kind": kind}
    if kind == "box":
        mesh = primitive("box", rng.uniform(0.04, 0.5, size=3))
    elif kind == "cylinder":
        r, h = rng.uniform(0.03, 0.4), rng.uniform(0.04, 0.5)
        R = _rot_x(math.pi / 2) if rng.random() < 0.3 else np.eye(3)
        mesh = primitive("cylinder", (r, r, h), R=R)
    elif kind == "ellipsoid":
        mesh = primitive("sphere", rng.uniform(0.05, 0.4) * rng.uniform(0.6, 1.4, size=3))
    elif kind == "cone":
        r = rng.uniform(0.05, 0.4)
        mesh = primitive("cone", (r, r, rng.uniform(0.05, 0.45)), R=_rot_x(math.pi) if rng.random() < 0.2 else None)
    elif kind == "composite":
        mesh = _composite(rng)
    elif kind == "lidded_box":
        size = (rng.uniform(0.08, 0.4), rng.uniform(0.1, 0.45), rng.uniform(0.06, 0.3))
        angle = 0.0 if rng.random() < 0.15 else rng.uniform(0.0, math.radians(150.0))
        mesh = lidded_box(size, angle, rng.uniform(0.006, 0.025))
        info["lid_angle_rad"] = angle
    elif kind == "drawer":
        size = (rng.uniform(0.15, 0.45), rng.uniform(0.15, 0.5), rng.uniform(0.08, 0.4))
        travel = 0.0 if rng.random() < 0.15 else rng.uniform(0.0, 0.8) * size[0]
        mesh = drawer(size, travel, rng)
        info["travel_m"] = travel
    elif kind == "thin":
        if rng.random() < 0.5:  # board / book / plate lying flat or a panel standing
            size = np.array([rng.uniform(0.08, 0.5), rng.uniform(0.05, 0.4), rng.uniform(0.004, 0.03)])
            R = _rot_x(math.pi / 2) if rng.random() < 0.25 else np.eye(3)
            mesh = primitive("box", size, R=R)
        elif rng.random() < 0.6:  # disc
            r = rng.uniform(0.05, 0.35)
            mesh = primitive("cylinder", (r, r, rng.uniform(0.004, 0.025)))
        else:  # pole / stick
            r = rng.uniform(0.01, 0.04)
            mesh = primitive("cylinder", (r, r, rng.uniform(0.15, 0.5)),
                             R=_rot_x(math.pi / 2) if rng.random() < 0.5 else None)
    elif kind == "tray":
        mesh = _tray(rng)
    else:  # torus
        R = rng.uniform(0.05, 0.25)
        mesh = torus(R, R * rng.uniform(0.15, 0.5), R=_rot_x(math.pi / 2) if rng.random() < 0.3 else None)
    mesh = rest_on_table(mesh)
    mesh = transform(mesh, _rot_z(rng.uniform(0.0, 2.0 * math.pi)))
    return mesh, info


# --------------------------------------------------------------------------- camera


def random_camera_pose(rng: np.random.Generator, target, view: ViewConfig | None = None) -> np.ndarray:
    """A camera pose X_WC (4x4) on the upper hemisphere around ``target`` (see :class:`ViewConfig`)."""
    view = view if view is not None else ViewConfig()
    dist = rng.uniform(*view.distance_m)
    el = math.radians(rng.uniform(*view.elevation_deg))
    az = rng.uniform(0.0, 2.0 * math.pi)
    target = np.asarray(target, dtype=np.float64)
    eye = target + dist * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    aim = target + rng.normal(0.0, view.look_at_jitter_m, size=3)
    return look_at(eye, aim, math.radians(rng.normal(0.0, view.roll_deg)))


def render_depth_points(mesh: Mesh, X_WC: np.ndarray, rng: np.random.Generator,
                        camera: DepthCameraConfig | None = None, noise: bool = True) -> np.ndarray:
    """Points (M, 3) in W that the depth camera at X_WC sees on ``mesh`` (one per pixel, see module docstring)."""
    import open3d as o3d

    camera = camera if camera is not None else DepthCameraConfig()

    v, f = mesh
    X_WC = np.asarray(X_WC, dtype=np.float64)
    if X_WC.shape != (4, 4):
        raise ValueError(f"X_WC: expected a 4x4 pose, got shape {X_WC.shape}")
    R_WC, p_WC = X_WC[:3, :3], X_WC[:3, 3]
    fpx = camera.focal_px
    cx, cy = (camera.width - 1) / 2.0, (camera.height - 1) / 2.0
    # Image footprint of the mesh (vertices in front of the camera only).
    v_C = (v - p_WC) @ R_WC
    front = v_C[:, 2] > 1e-3
    if not np.any(front):
        return np.zeros((0, 3))
    u = v_C[front, 0] / v_C[front, 2] * fpx + cx
    w = v_C[front, 1] / v_C[front, 2] * fpx + cy
    u0, u1 = int(max(0, math.floor(u.min()) - 1)), int(min(camera.width - 1, math.ceil(u.max()) + 1))
    w0, w1 = int(max(0, math.floor(w.min()) - 1)), int(min(camera.height - 1, math.ceil(w.max()) + 1))
    if u0 > u1 or w0 > w1:
        return np.zeros((0, 3))
    uu, ww = np.meshgrid(np.arange(u0, u1 + 1, dtype=np.float64), np.arange(w0, w1 + 1, dtype=np.float64))
    uu, ww = uu.ravel(), ww.ravel()
    d_C = np.stack([(uu - cx) / fpx, (ww - cy) / fpx, np.ones_like(uu)], axis=1)  # z = 1: t_hit is the depth
    d_W = d_C @ R_WC.T
    rays = np.concatenate([np.broadcast_to(p_WC, d_W.shape), d_W], axis=1).astype(np.float32)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(v.astype(np.float32)), o3d.core.Tensor(f.astype(np.uint32)))
    hit = scene.cast_rays(o3d.core.Tensor(rays))
    z = hit["t_hit"].numpy().astype(np.float64)
    ok = np.isfinite(z) & (z > camera.min_range_m) & (z < camera.max_range_m)
    if noise:
        n_W = hit["primitive_normals"].numpy().astype(np.float64)
        cos_inc = np.abs(np.sum(n_W * d_W, axis=1)) / np.linalg.norm(d_W, axis=1)
        inc = np.degrees(np.arccos(np.clip(cos_inc, 0.0, 1.0)))
        p_miss = np.clip((inc - camera.grazing_start_deg) / (camera.max_incidence_deg - camera.grazing_start_deg),
                         0.0, 1.0)
        ok &= rng.random(z.shape) >= np.maximum(p_miss, camera.dropout)
    uu, ww, z = uu[ok], ww[ok], z[ok]
    if noise and z.size:
        a, b, c = camera.axial_noise_m
        z = z + rng.normal(0.0, 1.0, z.shape) * (a + b * (z - c) ** 2)
        if camera.disparity_step_px > 0:
            fb = fpx * camera.baseline_m
            disp = np.round(fb / z / camera.disparity_step_px) * camera.disparity_step_px
            z = fb / disp
        uu = uu + rng.normal(0.0, camera.lateral_noise_px, uu.shape)
        ww = ww + rng.normal(0.0, camera.lateral_noise_px, ww.shape)
    p_C = np.stack([(uu - cx) / fpx * z, (ww - cy) / fpx * z, z], axis=1)
    return p_C @ R_WC.T + p_WC


def partial_view_cloud(mesh: Mesh, X_WC: np.ndarray, rng: np.random.Generator,
                       config: CloudConfig | None = None, noise: bool = True) -> np.ndarray:
    """Rendered, table-cut and resampled cloud (n_points, 3) in W; raises ValueError if the view
    has < min_points points."""
    config = config if config is not None else CloudConfig()
    pts = render_depth_points(mesh, X_WC, rng, config.camera, noise)
    if noise and rng.random() < config.table_cut_probability:
        keep = pts[:, 2] > rng.uniform(0.0, config.table_cut_max_m)
        if keep.sum() >= config.min_points:
            pts = pts[keep]
    if len(pts) < config.min_points:
        raise ValueError(f"partial view: only {len(pts)} points visible, expected >= {config.min_points}")
    return resample_points(pts, config.n_points, rng).astype(np.float32)


def random_cloud(rng: np.random.Generator, config: CloudConfig | None = None,
                 kind: str | None = None) -> tuple[np.ndarray, dict]:
    """One random shape seen from one random viewpoint: ((n_points, 3) float32 in W, info)."""
    config = config if config is not None else CloudConfig()
    for _ in range(20):
        mesh, info = random_shape(rng, kind)
        lo, hi = mesh[0].min(axis=0), mesh[0].max(axis=0)
        X_WC = random_camera_pose(rng, 0.5 * (lo + hi), config.view)
        try:
            return partial_view_cloud(mesh, X_WC, rng, config), info
        except ValueError:
            continue
    raise RuntimeError("random_cloud: 20 draws in a row gave too few visible points; check CloudConfig")


def generate_clouds(n: int, seed: int, config: CloudConfig | None = None, start: int = 0,
                    progress: bool = False) -> tuple[np.ndarray, list[str]]:
    """Clouds ``start .. start+n-1`` of the dataset with this seed: ((n, n_points, 3) float32, kinds).

    Sample i uses ``np.random.default_rng([seed, i])`` only, so slices agree with a full run.
    """
    config = config if config is not None else CloudConfig()
    if n < 0:
        raise ValueError(f"n: expected >= 0, got {n}")
    out = np.empty((n, config.n_points, 3), dtype=np.float32)
    kinds = []
    it = range(n)
    if progress:
        from tqdm import tqdm

        it = tqdm(it, desc=f"clouds (seed {seed})", unit="cloud")
    for j in it:
        cloud, info = random_cloud(np.random.default_rng([seed, start + j]), config)
        out[j] = cloud
        kinds.append(info["kind"])
    return out, kinds


def lidded_box_view(lid_angle_rad: float, rng: np.random.Generator, size=(0.20, 0.30, 0.15),
                    p_WO=(0.0, 0.0, 0.0), yaw_rad: float = 0.0, camera_position=(1.3, 0.0, 0.7),
                    config: CloudConfig | None = None, noise: bool = True) -> np.ndarray:
    """The thesis' lidded box seen by a fixed camera: cloud (n_points, 3) in W.

    The box (depth x 0.20, width y 0.30, height z 0.15 m by default; front
    towards +x, lid hinged at the back top edge) is yawed by ``yaw_rad`` and
    moved by ``p_WO``; the camera at ``camera_position`` looks at the origin.
    """
    mesh = transform(lidded_box(size, lid_angle_rad), _rot_z(yaw_rad), p_WO)
    X_WC = look_at(camera_position, (0.0, 0.0, 0.0))
    return partial_view_cloud(mesh, X_WC, rng, config, noise)
