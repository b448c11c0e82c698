"""Object segmentation from an organised, coloured point cloud (numpy / scipy / open3d; no Drake).

docs/method.md section 3 ("Segmentation"), thesis sections 3.6 and 6.4. The thesis
segments a solid, known-colour object from the Kinect's organised cloud with
the organised connected-component segmentation of Trevor et al. (2013), and
derives the object frame from the centre of the segment's bounding box. This
module does the same steps on arrays:

1. **Table plane** (:func:`fit_table_plane`, once per run, not per frame):
   RANSAC (``open3d`` ``segment_plane``, seeded with
   ``open3d.utility.random.seed``) on a strided subset of the workspace's
   points, then a least-squares refit on the inliers. The plane is
   ``[a, b, c, d]`` with ``a x + b y + c z + d = 0``, unit normal, ``c > 0``
   (world z up), so ``height(p) = [a, b, c] . p + d`` is the signed distance
   above the table [m].
2. **Colour** (:func:`target_colour_mask`): HSV thresholds (hue range in
   degrees, minimum saturation and value in [0, 1]); the objects are solid
   blue. The selection rests on hue and saturation; the value floor
   (``value_min``, default 0.05) only drops pixels too dark for a hue, so a
   face turned from the light stays in (docs/method.md section 3).
3. **Crop and table removal** (:func:`segment_object`): keep finite points of
   the target colour inside the axis-aligned workspace box (world frame, m)
   and higher than ``table_distance`` above the plane.
4. **Clustering** (:func:`cluster_organised`): connected components on the
   image grid, Trevor et al.'s organised connected components with a
   Euclidean comparator: two 4-neighbouring pixels are connected when both
   are kept and their 3-D points are closer than ``cluster_distance``.
   ``scipy.ndimage.label`` labels the graph. Which components are the
   object is ``cluster_rule`` (:func:`select_regions`): ``"all_regions"``
   (default) keeps every component of at least ``min_region_fraction`` of
   the largest one's pixels (a moving part cut off from the base by a
   shaded strip stays; specks go); ``"largest"`` keeps the largest only
   (thesis 3.6's rule, which drops such a part).
5. **Box and pose** (:func:`estimate_box`): the footprint rectangle is
   fitted in the table plane to the points of the lower band of heights
   ``[footprint_min_height, footprint_max_height]`` (the object's base: for
   the box, below the lid, so neither the lid's front lip when closed nor the
   raised lid when open shifts it; the thesis' plain bounding-box centre is
   ``footprint_max_height = inf``; it is also the fallback when the band has
   too few points or is narrower than ``footprint_min_extent``, as when only
   one face is seen). The camera sees two faces of the base, an
   L in the plane, so the rectangle's orientation comes from the
   closeness criterion of L-shape fitting (Zhang et al. 2017, "Efficient
   L-shape fitting for vehicle detection using laser scanners"), not from a
   minimum-area rectangle (ambiguous for an L). The rectangle's axes are
   defined up to multiples of 90 degrees; the yaw closest to
   ``nominal_yaw`` is taken. The object pose X_WO is the footprint centre
   on the table (the centre of the object's bottom face, as the station's
   frame O) with that yaw; the bounding box is that of all the segment's
   points in the same yawed frame.
6. **Resampling** (:func:`resample_points`): exactly N = 2048 points drawn
   uniformly from the segment (thesis 6.4) with a seeded generator, without
   replacement when the segment has at least N points, otherwise all points
   plus draws with replacement.

:func:`process_frame` runs 3-6 on one frame. Arrays: an organised cloud of an
H x W image is ``xyz (P, 3)`` float [m], world frame, row-major as the image
(P = H * W), non-finite rows for pixels without a return, and ``rgb (P, 3)``
uint8. Missing returns are not errors; malformed arrays raise ValueError.
"""

import dataclasses as dc
import functools
import math

import numpy as np
from scipy import ndimage

from drake_skill import typed_yaml
from drake_skill.common import N_POINTS

__all__ = [
    "BOUNDING_BOX_SIZE",
    "CLUSTER_RULES",
    "VALUE_MIN",
    "ObjectBox",
    "FrameResult",
    "SegmentPixels",
    "Segmentation",
    "SegmentationConfig",
    "check_organised_cloud",
    "cluster_organised",
    "estimate_box",
    "fit_footprint",
    "fit_table_plane",
    "hue_config",
    "process_frame",
    "resample_points",
    "segment_object",
    "segment_pixels",
    "select_regions",
    "target_colour_mask",
]


BOUNDING_BOX_SIZE = 7
"""``[cx, cy, cz, ex, ey, ez, yaw]``: see :class:`ObjectBox`."""

VALUE_MIN = 0.05
"""Default HSV value floor in [0, 1], for the segmenter and a scenario's ``object.colour``:
low, so that the colour test rests on hue and saturation (docs/method.md section 3)."""

CLUSTER_RULES = ("all_regions", "largest")
"""The values of :attr:`SegmentationConfig.cluster_rule` (see :func:`select_regions`)."""


@dc.dataclass
class SegmentationConfig:
    """Thresholds of the segmentation (all lengths in m, world frame, angles as named).

    workspace_min, workspace_max: corners of the axis-aligned crop box.
    hue_min_deg, hue_max_deg: hue range of the object's colour [deg, 0..360).
      A range with hue_min_deg > hue_max_deg wraps through 0 (reds).
    saturation_min, value_min: HSV saturation and value lower bounds in [0, 1].
    table_distance: points at most this high above the table plane are table.
    cluster_distance: largest 3-D gap between 4-neighbouring pixels of a cluster.
    cluster_rule: which clusters are the object: ``"all_regions"`` every
      cluster of at least ``min_region_fraction`` of the largest one's pixels,
      or ``"largest"`` the largest alone (thesis 3.6; with ``value_min`` 0.15
      it reproduces results from before issue 50).
    min_region_fraction: under ``"all_regions"``, smaller clusters than this
      fraction of the largest are specks and dropped, in [0, 1].
    min_points: the segment must have at least this many points for
      a frame to be valid (fewer: occluded or out of view).
    footprint_min_height, footprint_max_height: band of heights above the
      table whose points define the footprint (object base); ``inf`` as the
      upper bound gives the bounding box of all points (the thesis' choice).
    footprint_min_points: fewer band points than this: use all points.
    footprint_min_extent: a band footprint narrower than this (one face seen
      edge-on, e.g. a camera at table height) is replaced by that of all points [m].
    footprint_closeness: distance floor of the L-shape closeness score [m]:
      about the depth noise (the simulated camera has none; a Kinect needs more).
    nominal_yaw: the footprint's yaw is chosen among the four 90-degree
      equivalent ones as the closest to this [rad].
    plane_ransac_distance: RANSAC inlier distance [m].
    plane_ransac_iterations: RANSAC iterations.
    plane_stride: the plane is fitted on every plane_stride-th row and column.
    plane_max_tilt_deg: a fitted plane tilted more than this from the world's
      xy plane is rejected [deg].
    """

    workspace_min: list[float] = dc.field(default_factory=lambda: [0.20, -0.50, -0.05])
    workspace_max: list[float] = dc.field(default_factory=lambda: [1.10, 0.50, 0.60])
    hue_min_deg: float = 200.0
    hue_max_deg: float = 250.0
    saturation_min: float = 0.45
    value_min: float = VALUE_MIN
    table_distance: float = 0.004
    cluster_distance: float = 0.03
    cluster_rule: str = "all_regions"
    min_region_fraction: float = 0.01
    min_points: int = 1000
    footprint_min_height: float = 0.01
    footprint_max_height: float = 0.12
    footprint_min_points: int = 100
    footprint_min_extent: float = 0.02
    footprint_closeness: float = 0.001
    nominal_yaw: float = 0.0
    plane_ransac_distance: float = 0.005
    plane_ransac_iterations: int = 200
    plane_stride: int = 4
    plane_max_tilt_deg: float = 15.0

    def validate(self) -> "SegmentationConfig":
        """Raises ValueError naming the field that cannot work; returns self."""
        bad = functools.partial(typed_yaml.bad, "segmentation config")

        for name in ("workspace_min", "workspace_max"):
            v = getattr(self, name)
            if len(v) != 3 or not all(math.isfinite(x) for x in v):
                bad(name, v, "3 finite coordinates [m]")
        if not all(lo < hi for lo, hi in zip(self.workspace_min, self.workspace_max)):
            bad("workspace_min/workspace_max", (self.workspace_min, self.workspace_max),
                "workspace_min < workspace_max on every axis")
        for name in ("hue_min_deg", "hue_max_deg"):
            if not 0.0 <= getattr(self, name) <= 360.0:
                bad(name, getattr(self, name), "a hue in [0, 360] degrees")
        for name in ("saturation_min", "value_min"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                bad(name, getattr(self, name), "a fraction in [0, 1]")
        for name in ("table_distance", "cluster_distance", "plane_ransac_distance", "footprint_closeness",
                     "footprint_min_extent"):
            if not getattr(self, name) > 0:
                bad(name, getattr(self, name), "a positive length [m]")
        if self.cluster_rule not in CLUSTER_RULES:
            bad("cluster_rule", self.cluster_rule, " or ".join(repr(r) for r in CLUSTER_RULES))
        if not 0.0 <= self.min_region_fraction <= 1.0:
            bad("min_region_fraction", self.min_region_fraction, "a fraction in [0, 1]")
        if self.min_points < 1:
            bad("min_points", self.min_points, "at least 1")
        if not self.footprint_min_height < self.footprint_max_height:
            bad("footprint_min_height/footprint_max_height",
                (self.footprint_min_height, self.footprint_max_height), "min < max")
        if self.footprint_min_points < 3:
            bad("footprint_min_points", self.footprint_min_points, "at least 3")
        if not math.isfinite(self.nominal_yaw):
            bad("nominal_yaw", self.nominal_yaw, "a finite angle [rad]")
        if self.plane_ransac_iterations < 1:
            bad("plane_ransac_iterations", self.plane_ransac_iterations, "at least 1")
        if self.plane_stride < 1:
            bad("plane_stride", self.plane_stride, "at least 1")
        if not 0 < self.plane_max_tilt_deg <= 90:
            bad("plane_max_tilt_deg", self.plane_max_tilt_deg, "an angle in (0, 90] degrees")
        return self


# --------------------------------------------------------------------------- input


def check_organised_cloud(xyz, rgb, image_shape) -> tuple[np.ndarray, np.ndarray]:
    """Validates an organised cloud; returns ``(xyz (P, 3), rgb (P, 3) uint8)``.

    xyz: (P, 3) float, m; non-finite rows are pixels without a return (allowed).
    rgb: (P, 3) uint8. image_shape: (H, W) with H * W = P. Arrays are not copied
    when they already have these dtypes (a transposed (3, P) view is fine).
    """
    shape = tuple(int(s) for s in image_shape) if np.ndim(image_shape) == 1 else None
    if shape is None or len(shape) != 2 or min(shape) < 1:
        raise ValueError(f"image_shape: expected (height, width) of positive ints, got {image_shape!r}")
    n = shape[0] * shape[1]
    xyz = np.asarray(xyz)
    if xyz.ndim != 2 or xyz.shape != (n, 3):
        raise ValueError(f"xyz: expected shape ({n}, 3) for an organised {shape[0]}x{shape[1]} cloud, "
                         f"got {xyz.shape}")
    if not np.issubdtype(xyz.dtype, np.floating):
        raise ValueError(f"xyz: expected a float array (non-finite rows = no return), got dtype {xyz.dtype}")
    rgb = np.asarray(rgb)
    if rgb.shape != (n, 3):
        raise ValueError(f"rgb: expected shape ({n}, 3) like xyz, got {rgb.shape}")
    if rgb.dtype != np.uint8:
        raise ValueError(f"rgb: expected dtype uint8 (0..255 per channel), got {rgb.dtype}")
    return xyz, rgb


def _check_points(points, name: str, min_rows: int) -> np.ndarray:
    """(M, 3) finite float64 array, or ValueError naming ``name``."""
    arr = np.asarray(points)
    if arr.dtype == object or not np.issubdtype(arr.dtype, np.number):
        raise ValueError(f"{name}: expected a numeric array of shape (M, 3), got dtype {arr.dtype}")
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name}: expected shape (M, 3), got {arr.shape}")
    if arr.shape[0] < min_rows:
        raise ValueError(f"{name}: expected at least {min_rows} points, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.isfinite(arr).all(axis=1)))
        raise ValueError(f"{name}: {bad} of {arr.shape[0]} points are NaN or infinite; "
                         "drop missing returns first")
    return arr.astype(np.float64, copy=False)


def _check_plane(plane) -> np.ndarray:
    p = np.asarray(plane, dtype=float)
    if p.shape != (4,) or not np.all(np.isfinite(p)):
        raise ValueError(f"plane: expected 4 finite coefficients [a, b, c, d], got {np.asarray(plane).shape}: {plane}")
    norm = np.linalg.norm(p[:3])
    if not norm > 1e-9:
        raise ValueError(f"plane: normal [a, b, c] = {p[:3]} has zero length")
    p = p / norm
    return -p if p[2] < 0 else p


# --------------------------------------------------------------------------- colour


_LUT_BITS = 6
"""Bits per channel of the colour lookup table (64^3 = 262144 entries)."""


def _hsv_in_range(rgb: np.ndarray, config: SegmentationConfig) -> np.ndarray:
    """Exact HSV test of colours (K, 3) in 0..255 (float); (K,) bool."""
    r, g, b = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    mx = np.maximum(np.maximum(r, g), b)
    chroma = mx - np.minimum(np.minimum(r, g), b)
    keep = (mx >= config.value_min * 255.0) & (chroma >= config.saturation_min * mx) & (chroma > 0)
    c = np.where(chroma > 0, chroma, 1.0)
    hue = np.where(mx == r, ((g - b) / c) % 6.0,
                   np.where(mx == g, (b - r) / c + 2.0, (r - g) / c + 4.0)) * 60.0
    lo, hi = config.hue_min_deg, config.hue_max_deg
    return keep & (((hue >= lo) & (hue <= hi)) if lo <= hi else ((hue >= lo) | (hue <= hi)))


@functools.lru_cache(maxsize=8)
def _colour_lut(hue_min, hue_max, saturation_min, value_min) -> np.ndarray:
    config = SegmentationConfig(hue_min_deg=hue_min, hue_max_deg=hue_max,
                                saturation_min=saturation_min, value_min=value_min)
    levels = (np.arange(1 << _LUT_BITS) << (8 - _LUT_BITS)) + (1 << (7 - _LUT_BITS)) - 0.5
    grid = np.stack(np.meshgrid(levels, levels, levels, indexing="ij"), axis=-1).reshape(-1, 3)
    return _hsv_in_range(grid, config)


def target_colour_mask(rgb, config: SegmentationConfig) -> np.ndarray:
    """(P,) bool: pixels whose HSV colour lies in the configured ranges. rgb: (P, 3) uint8.

    Looks the colour up in a table of 64 levels per channel (built once per
    threshold set), each entry the exact HSV test at its bin's centre, so a
    threshold is honoured to within half a bin (2 of 255).
    """
    rgb = np.asarray(rgb)
    if rgb.ndim != 2 or rgb.shape[1] != 3 or rgb.dtype != np.uint8:
        raise ValueError(f"rgb: expected a uint8 array of shape (P, 3), got {rgb.dtype} {rgb.shape}")
    lut = _colour_lut(float(config.hue_min_deg), float(config.hue_max_deg),
                      float(config.saturation_min), float(config.value_min))
    shift = 8 - _LUT_BITS
    key = (rgb[:, 0] >> shift).astype(np.int32) << (2 * _LUT_BITS)
    key |= (rgb[:, 1] >> shift).astype(np.int32) << _LUT_BITS
    key |= rgb[:, 2] >> shift
    return lut[key]


# --------------------------------------------------------------------------- table plane


def fit_table_plane(xyz, config: SegmentationConfig, image_shape, seed: int = 0) -> np.ndarray:
    """Fits the table plane to an organised cloud; returns ``[a, b, c, d]`` (see module docstring).

    Uses every ``plane_stride``-th row and column of the finite points inside
    the workspace crop; RANSAC (open3d, seeded with ``seed``, all
    ``plane_ransac_iterations`` run) then a least-squares refit on the
    inliers. Raises ValueError when there are fewer than 100 such points or
    the plane is tilted more than ``plane_max_tilt_deg`` from horizontal.
    """
    import open3d as o3d

    xyz = np.asarray(xyz)
    check_organised_cloud(xyz, np.broadcast_to(np.uint8(0), xyz.shape), image_shape)
    h, w = int(image_shape[0]), int(image_shape[1])
    s = config.plane_stride
    sub = xyz.reshape(h, w, 3)[::s, ::s].reshape(-1, 3).astype(np.float64)
    lo, hi = np.asarray(config.workspace_min), np.asarray(config.workspace_max)
    with np.errstate(invalid="ignore"):
        keep = np.isfinite(sub).all(axis=1) & np.all((sub >= lo) & (sub <= hi), axis=1)
    sub = sub[keep]
    if sub.shape[0] < 100:
        raise ValueError(f"xyz: only {sub.shape[0]} finite points in the workspace at stride {s}; "
                         "cannot fit the table plane (need 100)")
    o3d.utility.random.seed(int(seed))
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(sub))
    # probability=1 runs every iteration. open3d evaluates the iterations on
    # OpenMP threads and, by default, stops early once its confidence bound is
    # met; how many iterations ran before that check then depends on thread
    # timing, and on a loaded machine the same seed gave two different planes
    # within 200 calls. With all iterations run, the set of sampled triples is
    # fixed by the seed and the best of them (most inliers, then least RMSE)
    # does not depend on the order in which threads finish.
    _, inliers = cloud.segment_plane(config.plane_ransac_distance, 3, config.plane_ransac_iterations, 1.0)
    pts = sub[np.asarray(inliers)]
    centre = pts.mean(axis=0)
    normal = np.linalg.svd(pts - centre, full_matrices=False)[2][2]
    if normal[2] < 0:
        normal = -normal
    tilt = math.degrees(math.acos(min(1.0, abs(normal[2]))))
    if tilt > config.plane_max_tilt_deg:
        raise ValueError(f"xyz: the dominant plane is tilted {tilt:.1f} deg from horizontal "
                         f"(plane_max_tilt_deg = {config.plane_max_tilt_deg}); is the table in the workspace?")
    return np.r_[normal, -normal @ centre]


# --------------------------------------------------------------------------- segmentation


@dc.dataclass
class Segmentation:
    """The object's pixels in one frame.

    indices: (M,) int64 flat pixel indices (row * W + column), ascending.
    points: (M, 3) float64 world coordinates [m] of those pixels.
    n_candidates: pixels that passed colour, crop and table removal.
    n_clusters: connected components among them.
    image_shape: (H, W).
    """

    indices: np.ndarray
    points: np.ndarray
    n_candidates: int
    n_clusters: int
    image_shape: tuple[int, int]

    def mask(self) -> np.ndarray:
        """(H, W) bool image of the object's pixels."""
        m = np.zeros(self.image_shape[0] * self.image_shape[1], dtype=bool)
        m[self.indices] = True
        return m.reshape(self.image_shape)


def cluster_organised(indices, xyz, image_shape, max_distance: float) -> tuple[int, np.ndarray]:
    """Organised connected components (Trevor et al. 2013, Euclidean comparator).

    indices: (K,) ascending flat pixel indices of the candidate points; xyz:
    (P, 3) the organised cloud (finite at ``indices``); two candidates that
    are 4-neighbours on the image grid are connected when their points are
    closer than ``max_distance`` [m]. Returns ``(n_components, labels (K,))``
    with labels in 0..n_components-1.

    The graph is labelled with ``scipy.ndimage.label`` on a grid of twice the
    resolution (over the candidates' bounding rectangle): even cells are
    pixels, the odd cells between two of them are set when their edge exists,
    so 4-connected regions of that grid are the graph's components.
    """
    indices = np.asarray(indices, dtype=np.int64)
    h, w = int(image_shape[0]), int(image_shape[1])
    if indices.size == 0:
        return 0, np.zeros(0, dtype=np.int32)
    rows, cols = np.divmod(indices, w)
    r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols.min(), cols.max() + 1
    cand = np.zeros((r1 - r0, c1 - c0), dtype=bool)
    cand[rows - r0, cols - c0] = True
    pts = np.asarray(xyz).reshape(h, w, 3)[r0:r1, c0:c1]
    limit = max_distance * max_distance
    grid = np.zeros((2 * cand.shape[0] - 1, 2 * cand.shape[1] - 1), dtype=bool)
    grid[::2, ::2] = cand
    with np.errstate(invalid="ignore"):
        d = pts[:, 1:] - pts[:, :-1]
        grid[::2, 1::2] = cand[:, 1:] & cand[:, :-1] & (np.einsum("ijk,ijk->ij", d, d) < limit)
        d = pts[1:] - pts[:-1]
        grid[1::2, ::2] = cand[1:] & cand[:-1] & (np.einsum("ijk,ijk->ij", d, d) < limit)
    labels, n = ndimage.label(grid)
    return int(n), labels[::2, ::2][cand].astype(np.int32) - 1


def select_regions(labels, n_clusters: int, rule: str = "all_regions", min_fraction: float = 0.01) -> np.ndarray:
    """The candidates that the cluster rule keeps as the object; (K,) bool.

    labels: (K,) cluster labels in 0..n_clusters-1 (:func:`cluster_organised`).
    ``rule`` ``"largest"``: the largest cluster (the first on a tie).
    ``"all_regions"``: every cluster with at least ``min_fraction`` times the
    largest cluster's pixel count (a cluster of exactly that size stays).
    """
    labels = np.asarray(labels)
    if n_clusters <= 1:
        return np.ones(labels.shape, dtype=bool)
    sizes = np.bincount(labels, minlength=n_clusters)
    if rule == "largest":
        return labels == np.argmax(sizes)
    if rule != "all_regions":
        raise ValueError(f"rule: expected one of {CLUSTER_RULES}, got {rule!r}")
    return (sizes >= min_fraction * sizes.max())[labels]


def segment_object(xyz, rgb, plane, config: SegmentationConfig, image_shape) -> Segmentation:
    """Steps 2-4 of the module docstring: colour, crop, table removal, the clusters of ``cluster_rule``.

    xyz (P, 3) float [m], rgb (P, 3) uint8, plane (4,) [a, b, c, d];
    image_shape (H, W) with H * W = P. An object that is not visible gives an
    empty segmentation (M = 0), not an error.
    """
    xyz, rgb = check_organised_cloud(xyz, rgb, image_shape)
    plane = _check_plane(plane)
    shape = (int(image_shape[0]), int(image_shape[1]))
    idx = np.flatnonzero(target_colour_mask(rgb, config))
    p = xyz[idx]
    lo, hi = np.asarray(config.workspace_min), np.asarray(config.workspace_max)
    with np.errstate(invalid="ignore"):   # non-finite rows compare False
        keep = np.all((p >= lo) & (p <= hi), axis=1)
        keep &= p @ plane[:3] + plane[3] > config.table_distance
    idx, p = idx[keep], p[keep]
    n_clusters, labels = cluster_organised(idx, xyz, shape, config.cluster_distance)
    if n_clusters > 1:
        sel = select_regions(labels, n_clusters, config.cluster_rule, config.min_region_fraction)
        idx, p = idx[sel], p[sel]
    return Segmentation(idx, p.astype(np.float64), int(keep.sum()), n_clusters, shape)


def hue_config(config: SegmentationConfig) -> SegmentationConfig:
    """The colour test widened to the object's hue: the same hue range, half the saturation floor and
    the value floor at most :data:`VALUE_MIN`. Its pixels are those a wider colour range could add:
    on a rendered Open lid whose shaded faces fail ``value_min`` 0.5 they are the object's visible
    pixels to within 19 of 21,656 (the renderer's labels)."""
    return dc.replace(config, saturation_min=0.5 * config.saturation_min, value_min=min(config.value_min, VALUE_MIN))


@dc.dataclass
class SegmentPixels:
    """One organised frame's pixels as the segmenter saw them (an H x W image).

    rgb: (H, W, 3) uint8 colour image. Then (H, W) bool masks, each within the
    one before: hue, the pixels of the object's hue (:func:`hue_config`'s colour
    test); coloured, those that pass the colour test (:func:`target_colour_mask`);
    kept, the segment's pixels (:meth:`Segmentation.mask`). Without ground truth
    (the robot), hue stands for the object's pixels: ``kept / hue`` is the share
    the segment holds, hue but not coloured is what the colour range drops, and
    coloured but not kept what the crop, the table removal and the cluster rule drop.
    """

    rgb: np.ndarray
    hue: np.ndarray
    coloured: np.ndarray
    kept: np.ndarray

    def counts(self) -> tuple[int, int, int]:
        """(pixels of the object's hue, object-coloured pixels, kept pixels)."""
        return tuple(int(np.count_nonzero(m)) for m in (self.hue, self.coloured, self.kept))

    def downscaled(self, stride: int) -> "SegmentPixels":
        """Every ``stride``-th pixel of each row and column (nearest-pixel sampling: the masks stay nested)."""
        arrays = (self.rgb, self.hue, self.coloured, self.kept)
        return SegmentPixels(*(np.ascontiguousarray(a[::stride, ::stride]) for a in arrays))


def segment_pixels(rgb, config: SegmentationConfig, image_shape,
                   segmentation: "Segmentation | None" = None) -> SegmentPixels:
    """:class:`SegmentPixels` of one frame: rgb (P, 3) uint8 (P = H * W) and the frame's
    :func:`segment_object` result (None: nothing kept, as before the table plane is known)."""
    shape = (int(image_shape[0]), int(image_shape[1]))
    rgb = np.asarray(rgb)
    kept = segmentation.mask() if segmentation is not None else np.zeros(shape, dtype=bool)
    hue, coloured = (target_colour_mask(rgb, c).reshape(shape) for c in (hue_config(config), config))
    return SegmentPixels(rgb.reshape(*shape, 3).copy(), hue, coloured, kept)


# --------------------------------------------------------------------------- box


def _wrap(angle):
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi


def _closeness(xy: np.ndarray, thetas: np.ndarray, floor: float) -> np.ndarray:
    """L-shape closeness score of each candidate axis angle (Zhang et al. 2017). xy: (M, 2)."""
    c, s = np.cos(thetas), np.sin(thetas)
    u = xy[:, :1] * c + xy[:, 1:] * s            # (M, A) coordinate along e1
    v = -xy[:, :1] * s + xy[:, 1:] * c           # along e2
    du = np.minimum(u.max(axis=0) - u, u - u.min(axis=0))
    dv = np.minimum(v.max(axis=0) - v, v - v.min(axis=0))
    return np.sum(1.0 / np.maximum(np.minimum(du, dv), floor), axis=0)


def _plateau_centre(score: np.ndarray) -> int:
    """Index of the middle of the best scores (ties: every point closer than the floor)."""
    top = np.flatnonzero(score >= score.max() * (1.0 - 1e-9))
    return int(top[top.size // 2])


def fit_footprint(xy, nominal_yaw: float = 0.0, closeness: float = 0.001,
                  max_points: int = 600) -> tuple[np.ndarray, np.ndarray, float]:
    """Rectangle in the plane fitted to points of its sides (an L or a full outline).

    xy: (M >= 3, 2) [m]. The axis angle maximises the closeness score over
    [0, 90) degrees (2 degree grid, then 0.1 degree refinement); the
    rectangle is the extent of the points along those axes. Angles whose
    scores tie for the best (points all within ``closeness`` of the sides)
    give the middle one. Of the four
    equivalent yaws the one nearest ``nominal_yaw`` is returned, with the
    extents ordered to match. At most ``max_points`` evenly strided points
    are scored. Returns ``(centre (2,), extents (2,) along the yawed x and y, yaw in [-pi, pi))``.
    """
    xy = np.asarray(xy)
    if xy.ndim != 2 or xy.shape[1] != 2 or xy.shape[0] < 3:
        raise ValueError(f"xy: expected shape (M >= 3, 2), got {xy.shape}")
    if not np.all(np.isfinite(xy)):
        raise ValueError("xy: contains NaN or infinite coordinates")
    xy = xy.astype(np.float64)
    sub = xy[:: max(1, int(np.ceil(xy.shape[0] / max_points)))]
    sub = sub - sub.mean(axis=0)
    coarse = np.deg2rad(np.arange(0.0, 90.0, 2.0))
    best = coarse[_plateau_centre(_closeness(sub, coarse, closeness))]
    fine = best + np.deg2rad(np.arange(-2.0, 2.0001, 0.1))
    theta = float(fine[_plateau_centre(_closeness(sub, fine, closeness))])
    # Among theta + k * 90 degrees, the yaw nearest the nominal one.
    k = int(np.round((nominal_yaw - theta) / (np.pi / 2)))
    yaw = float(_wrap(theta + k * np.pi / 2))
    c, s = math.cos(yaw), math.sin(yaw)
    u = xy[:, 0] * c + xy[:, 1] * s
    v = -xy[:, 0] * s + xy[:, 1] * c
    cu, cv = 0.5 * (u.max() + u.min()), 0.5 * (v.max() + v.min())
    centre = np.array([cu * c - cv * s, cu * s + cv * c])
    return centre, np.array([np.ptp(u), np.ptp(v)]), yaw


@dc.dataclass
class ObjectBox:
    """Bounding box and pose estimate of the object.

    bounding_box: (7,) ``[cx, cy, cz, ex, ey, ez, yaw]``: centre (world, m),
      extents along the box's own x, y (rotated by yaw about world z) and z
      (m), yaw (rad) of all the segment's points. cz and ez are measured
      from the lowest to the highest point.
    position: (3,) the estimated origin of O [m]: centre of the footprint
      rectangle, on the table plane.
    yaw: yaw of O about world z [rad] (x_O, y_O along the footprint's sides).
    footprint_extents: (2,) the footprint rectangle's sides along x_O, y_O [m].
    """

    bounding_box: np.ndarray
    position: np.ndarray
    yaw: float
    footprint_extents: np.ndarray


def estimate_box(points, plane, config: SegmentationConfig) -> ObjectBox:
    """Step 5 of the module docstring. points: (M >= 3, 3) finite [m]; plane (4,)."""
    points = _check_points(points, "points", min_rows=3)
    plane = _check_plane(plane)
    height = points @ plane[:3] + plane[3]
    band = (height >= config.footprint_min_height) & (height <= config.footprint_max_height)
    fit = None
    if band.sum() >= config.footprint_min_points:
        fit = fit_footprint(points[band, :2], config.nominal_yaw, config.footprint_closeness)
    if fit is None or fit[1].min() < config.footprint_min_extent:
        fit = fit_footprint(points[:, :2], config.nominal_yaw, config.footprint_closeness)
    centre, extents, yaw = fit
    a, b, c, d = plane
    position = np.array([centre[0], centre[1], -(a * centre[0] + b * centre[1] + d) / c])
    cy, sy = math.cos(yaw), math.sin(yaw)
    u = points[:, 0] * cy + points[:, 1] * sy
    v = -points[:, 0] * sy + points[:, 1] * cy
    cu, cv = 0.5 * (u.max() + u.min()), 0.5 * (v.max() + v.min())
    z = points[:, 2]
    box = np.array([cu * cy - cv * sy, cu * sy + cv * cy, 0.5 * (z.max() + z.min()),
                    np.ptp(u), np.ptp(v), np.ptp(z), yaw])
    return ObjectBox(box, position, yaw, extents)


# --------------------------------------------------------------------------- resampling


def resample_points(points, n_points: int = N_POINTS, seed: "int | np.random.Generator" = 0) -> np.ndarray:
    """Exactly ``n_points`` rows drawn uniformly from ``points`` (M, 3); deterministic for a seed.

    The one resampler of the project (segmented frames and the PCAE's training
    views). M >= n_points: a random subset without replacement; M < n_points:
    all M points and ``n_points - M`` more drawn with replacement, shuffled.
    ``seed``: an int, or a ``numpy.random.Generator`` to draw from (advanced).
    Raises ValueError for an empty or non-finite cloud. Returns (n_points, 3) float64.
    """
    if np.ndim(points) == 2 and np.shape(points)[0] == 0:
        raise ValueError("points: cannot resample an empty cloud (shape (0, 3)); "
                         "check the segmentation found the object")
    points = _check_points(points, "points", min_rows=1)
    if int(n_points) != n_points or n_points < 1:
        raise ValueError(f"n_points: expected a positive integer, got {n_points!r}")
    rng = np.random.default_rng(seed)          # a Generator passes through unchanged
    m = points.shape[0]
    if m >= n_points:
        idx = rng.choice(m, size=int(n_points), replace=False)
    else:
        idx = np.concatenate([np.arange(m), rng.integers(0, m, size=int(n_points) - m)])
        rng.shuffle(idx)
    return points[idx]


# --------------------------------------------------------------------------- one frame


@dc.dataclass
class FrameResult:
    """Everything the segmenter computes from one frame.

    valid: the segment (the clusters kept) has at least ``min_points`` points.
    segmentation: the object's pixels and points (before resampling).
    points: (n_points, 3) resampled object cloud [m], world frame (None if not valid).
    box: bounding box and pose (None if not valid).
    """

    valid: bool
    segmentation: Segmentation
    points: np.ndarray | None = None
    box: ObjectBox | None = None


def process_frame(xyz, rgb, plane, config: SegmentationConfig, image_shape,
                  n_points: int = N_POINTS, seed: int = 0) -> FrameResult:
    """Segmentation, box, pose and resampling of one organised frame (steps 2-6).

    Shapes as :func:`segment_object`; ``seed`` seeds the resampling.
    """
    seg = segment_object(xyz, rgb, plane, config, image_shape)
    if seg.indices.size < config.min_points:
        return FrameResult(False, seg)
    box = estimate_box(seg.points, plane, config)
    return FrameResult(True, seg, resample_points(seg.points, n_points, seed), box)
