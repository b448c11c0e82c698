"""Tests for drake_skill.perception.shapes (procedural shapes and simulated depth views)."""

import math

import numpy as np
import pytest

from drake_skill.perception import pcae, shapes
from drake_skill.perception.segmentation import resample_points


def test_generate_clouds_is_seeded_and_sliceable():
    a, kinds_a = shapes.generate_clouds(5, seed=3)
    b, kinds_b = shapes.generate_clouds(5, seed=3)
    np.testing.assert_array_equal(a, b)
    assert kinds_a == kinds_b
    c, kinds_c = shapes.generate_clouds(2, seed=3, start=3)
    np.testing.assert_array_equal(c, a[3:])
    assert kinds_c == kinds_a[3:]
    d, _ = shapes.generate_clouds(5, seed=4)
    assert not np.array_equal(a, d)
    assert a.shape == (5, pcae.N_POINTS, 3) and a.dtype == np.float32
    assert np.all(np.isfinite(a))


@pytest.mark.parametrize("kind", shapes.SHAPE_KINDS)
def test_every_kind_gives_a_partial_view_on_the_table(kind):
    rng = np.random.default_rng(shapes.SHAPE_KINDS.index(kind))
    cloud, info = shapes.random_cloud(rng, kind=kind)
    assert info["kind"] == kind
    assert cloud.shape == (pcae.N_POINTS, 3)
    # Object rests on the table at the origin; noise is a few mm at most.
    assert cloud[:, 2].min() > -0.02
    ext = np.ptp(cloud, axis=0)
    assert np.all(ext < 1.2) and ext.max() > 0.02
    assert np.linalg.norm(0.5 * (cloud.min(0) + cloud.max(0))[:2]) < 0.6


def test_lidded_box_geometry():
    d, w, h, t = 0.2, 0.3, 0.15, 0.012
    v0, _ = shapes.lidded_box((d, w, h), 0.0, t)
    np.testing.assert_allclose(v0.min(0), [-d / 2, -w / 2, 0.0], atol=1e-12)
    np.testing.assert_allclose(v0.max(0), [d / 2, w / 2, h], atol=1e-12)
    v90, _ = shapes.lidded_box((d, w, h), math.pi / 2, t)
    # Upright lid behind the hinge at the back top edge.
    np.testing.assert_allclose(v90.max(0)[2], h - t + d, atol=1e-12)
    np.testing.assert_allclose(v90.min(0)[0], -d / 2 - t, atol=1e-12)
    np.testing.assert_allclose(v90.max(0)[0], d / 2, atol=1e-12)


def test_drawer_travel_moves_the_front():
    v0, _ = shapes.drawer((0.3, 0.35, 0.2), 0.0, np.random.default_rng(0))
    v1, _ = shapes.drawer((0.3, 0.35, 0.2), 0.12, np.random.default_rng(0))
    assert v1.max(0)[0] - v0.max(0)[0] == pytest.approx(0.12, abs=1e-12)
    np.testing.assert_allclose(v1.max(0)[1:], v0.max(0)[1:], atol=1e-12)  # only the front moves


def test_self_occlusion_noise_free():
    """A box seen from (1.3, 0, 0.7): only its front (+x) and top faces are visible."""
    d, w, h = 0.2, 0.3, 0.15
    mesh = shapes.primitive("box", (d, w, h), (0.0, 0.0, h / 2))
    X_WC = shapes.look_at((1.3, 0.0, 0.7), (0.0, 0.0, 0.0))
    pts = shapes.render_depth_points(mesh, X_WC, np.random.default_rng(0), noise=False)
    on_front = np.abs(pts[:, 0] - d / 2) < 1e-4
    on_top = np.abs(pts[:, 2] - h) < 1e-4
    assert np.all(on_front | on_top)
    assert on_front.sum() > 1000 and on_top.sum() > 1000
    # Front face is nearly facing the camera; it gets more pixels per area than the top.
    area_front, area_top = w * h, w * d
    assert on_front.sum() / area_front > on_top.sum() / area_top


def _plane_residual(distance, seed=0, noise=True):
    """Std (m) of the depth error of a fronto-parallel wall at ``distance`` m."""
    wall = shapes.primitive("box", (0.01, 0.6, 0.6), (0.0, 0.0, 0.0))
    X_WC = shapes.look_at((distance + 0.005, 0.0, 0.0001), (0.0, 0.0, 0.0))
    pts = shapes.render_depth_points(wall, X_WC, np.random.default_rng(seed), noise=noise)
    return pts, np.std(pts[:, 0] - 0.005)


def test_depth_noise_grows_with_distance_and_is_quantised():
    p1, s1 = _plane_residual(1.0)
    p2, s2 = _plane_residual(2.0)
    _, s0 = _plane_residual(1.0, noise=False)
    assert s0 < 1e-5
    # Nguyen et al. sigma_z: 1.9 mm at 1 m, 6.1 mm at 2 m; disparity quantisation steps
    # of 2.9 mm and 11.5 mm add 0.8 mm and 3.3 mm (uniform): 2.1 mm and 6.9 mm in all.
    assert 0.0018 < s1 < 0.0025
    assert 0.006 < s2 < 0.008
    # Quantised depth: far fewer distinct depths than points.
    assert len(np.unique(np.round(p2[:, 0], 7))) < 0.05 * len(p2)


def test_grazing_angle_returns_are_missing():
    """A floor seen at ~85 deg incidence returns almost nothing; at ~45 deg most pixels return."""
    floor = shapes.primitive("box", (0.6, 0.6, 0.01), (0.0, 0.0, -0.005))
    steep = shapes.look_at((1.0, 0.0, 1.0), (0.0, 0.0, 0.0))
    shallow = shapes.look_at((1.5, 0.0, 0.13), (0.0, 0.0, 0.0))
    counts = {}
    for name, X in (("steep", steep), ("shallow", shallow)):
        clean = shapes.render_depth_points(floor, X, np.random.default_rng(0), noise=False)
        noisy = shapes.render_depth_points(floor, X, np.random.default_rng(0), noise=True)
        counts[name] = len(noisy) / len(clean)
    assert counts["steep"] > 0.9
    assert counts["shallow"] < 0.3


def test_resample_points():
    rng = np.random.default_rng(0)
    few = rng.normal(size=(100, 3))
    out = resample_points(few, 2048, rng)
    assert out.shape == (2048, 3)
    assert len(np.unique(out, axis=0)) == 100  # all originals kept, the rest repeats
    many = rng.normal(size=(5000, 3))
    out = resample_points(many, 2048, rng)
    assert len(np.unique(out, axis=0)) == 2048  # without replacement
    with pytest.raises(ValueError, match=r"empty cloud"):
        resample_points(np.zeros((0, 3)), 2048, rng)


def test_errors():
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match=r"kind: expected one of .* got 'teapot'"):
        shapes.random_shape(rng, "teapot")
    with pytest.raises(ValueError, match="X_WC: expected a 4x4 pose"):
        shapes.render_depth_points(shapes.lidded_box(), np.eye(3), rng)
    with pytest.raises(ValueError, match="vertical"):
        shapes.look_at((0, 0, 2), (0, 0, 0))
    with pytest.raises(ValueError, match=r"only 0 points visible"):
        shapes.partial_view_cloud(shapes.lidded_box(), shapes.look_at((-1.0, 0.0, 0.5), (-3.0, 0.0, 0.5)), rng)
