"""Tests of drake_skill.action.quaternion against scipy's Rotation (scalar-last) as reference."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from drake_skill.action.quaternion import (
    as_quaternions,
    make_quaternions_continuous,
    quat_conjugate,
    quat_exp,
    quat_log,
    quat_multiply,
    quaternion_distance,
    rotation_angle,
)


def _wxyz(rot: Rotation) -> np.ndarray:
    return rot.as_quat()[..., [3, 0, 1, 2]]


def _rot(q_wxyz: np.ndarray) -> Rotation:
    return Rotation.from_quat(np.asarray(q_wxyz)[..., [1, 2, 3, 0]])


@pytest.fixture
def rotations():
    return Rotation.random(50, random_state=3)


def test_multiply_matches_rotation_composition(rotations):
    p, q = rotations[:25], rotations[25:]
    pq = quat_multiply(_wxyz(p), _wxyz(q))
    np.testing.assert_allclose(_rot(pq).as_matrix(), (p * q).as_matrix(), atol=1e-12)
    ident = quat_multiply(_wxyz(p), quat_conjugate(_wxyz(p)))
    np.testing.assert_allclose(ident, np.tile([1.0, 0, 0, 0], (25, 1)), atol=1e-12)


def test_log_is_half_rotation_vector_and_exp_inverts(rotations):
    q = _wxyz(rotations)
    q[q[:, 0] < 0] *= -1  # log is the principal branch on w >= 0
    r = quat_log(q)
    np.testing.assert_allclose(2.0 * r, rotations.as_rotvec(), atol=1e-12)
    np.testing.assert_allclose(quat_exp(r), q, atol=1e-12)
    # tiny rotations: no 0/0
    small = quat_exp(np.array([[1e-12, 0.0, 0.0], [0.0, 0.0, 0.0]]))
    np.testing.assert_allclose(small, [[1.0, 1e-12, 0, 0], [1.0, 0, 0, 0]], atol=1e-15)
    np.testing.assert_allclose(quat_log(small), [[1e-12, 0, 0], [0, 0, 0]], atol=1e-20)


def test_distance_and_angle_are_sign_invariant(rotations):
    p, q = _wxyz(rotations[:25]), _wxyz(rotations[25:])
    expected = (rotations[:25] * rotations[25:].inv()).magnitude()
    np.testing.assert_allclose(rotation_angle(p, q), expected, atol=1e-9)
    np.testing.assert_allclose(rotation_angle(-p, q), expected, atol=1e-9)
    np.testing.assert_allclose(quaternion_distance(p, -p), 0.0, atol=1e-15)
    d = quaternion_distance(p, q)
    np.testing.assert_allclose(d, quaternion_distance(-p, q))
    assert np.all(d <= np.sqrt(2.0) + 1e-12)


def test_make_continuous_flips_sign_jumps_and_follows_reference():
    angles = np.linspace(0.0, 3.0, 31)
    q = _wxyz(Rotation.from_rotvec(np.outer(angles, [0.0, 0.0, 1.0])))
    flipped = q.copy()
    flipped[[5, 6, 20]] *= -1.0
    out = make_quaternions_continuous(flipped)
    np.testing.assert_allclose(out, q, atol=1e-15)
    assert np.all(np.einsum("ij,ij->i", out[1:], out[:-1]) > 0)
    # with a reference on the other hemisphere the whole path is negated
    out_ref = make_quaternions_continuous(flipped, reference=-q[0])
    np.testing.assert_allclose(out_ref, -q, atol=1e-15)
    with pytest.raises(ValueError, match="reference"):
        make_quaternions_continuous(q, reference=np.ones(3))
    with pytest.raises(ValueError, match=r"q: expected shape \(T, 4\)"):
        make_quaternions_continuous(np.ones((3, 3)))


def test_as_quaternions_validates_and_normalises():
    q = np.array([[1.0, 0, 0, 0.005], [0, 0, 1.0, 0]])
    out = as_quaternions(q, name="demo q")
    np.testing.assert_allclose(np.linalg.norm(out, axis=1), 1.0, atol=1e-15)
    with pytest.raises(ValueError, match=r"demo q: quaternion at index \(1,\) has norm 0\.5"):
        as_quaternions([[1.0, 0, 0, 0], [0.5, 0, 0, 0]], name="demo q")
    with pytest.raises(ValueError, match="demo q: contains NaN"):
        as_quaternions([[np.nan, 0, 0, 1.0]], name="demo q")
    with pytest.raises(ValueError, match=r"demo q: expected shape \(\.\.\., 4\)"):
        as_quaternions(np.ones((2, 3)), name="demo q")


def test_rotation_matrix_matches_scipy(rotations):
    """quat_to_rotation_matrix against scipy, on unit and on scaled (non-unit) inputs."""
    from drake_skill.action.quaternion import quat_to_rotation_matrix

    for rot, scale in zip(rotations[:10], np.linspace(0.5, 3.0, 10)):
        R = quat_to_rotation_matrix(scale * _wxyz(rot))
        np.testing.assert_allclose(R, rot.as_matrix(), atol=1e-12)


def test_normalize_single_and_batched():
    from drake_skill.action.quaternion import quat_normalize

    np.testing.assert_allclose(quat_normalize([0.0, 0.0, 3.0, 4.0]), [0.0, 0.0, 0.6, 0.8], atol=1e-15)
    out = quat_normalize([[2.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.5]])
    np.testing.assert_allclose(out, [[1.0, 0, 0, 0], [0, 0, 0, 1.0]], atol=1e-15)


def test_single_quaternion_and_single_rotation_vector():
    """Shape (4,) and (3,) inputs: the functions broadcast over *zero* leading axes too."""
    out = as_quaternions(np.array([0.0, 0.0, 0.0, 1.001], dtype=np.float32))
    assert out.shape == (4,) and out.dtype == np.float64
    np.testing.assert_allclose(out, [0.0, 0.0, 0.0, 1.0], atol=1e-15)
    q = quat_exp([0.0, 0.0, np.pi / 4])
    np.testing.assert_allclose(q, [np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)], atol=1e-15)


def test_make_continuous_reference_edge_cases():
    q = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])
    # q[0] on the reference's hemisphere (dot 0.71), q[1] not (dot -0.71): only q[0] decides.
    ref = np.array([1.0, -1.0, 0.0, 0.0]) / np.sqrt(2.0)
    np.testing.assert_array_equal(make_quaternions_continuous(q, reference=ref), q)
    # a single sample is still put on the reference's hemisphere; the caller's array is not changed
    single = np.array([[0.0, 0.0, 0.0, 1.0]])
    np.testing.assert_array_equal(make_quaternions_continuous(single, reference=[0.0, 0.0, 0.0, -1.0]),
                                  [[0.0, 0.0, 0.0, -1.0]])
    np.testing.assert_array_equal(single, [[0.0, 0.0, 0.0, 1.0]])
    # an empty path stays empty, with or without a reference
    empty = make_quaternions_continuous(np.zeros((0, 4)), reference=[1.0, 0.0, 0.0, 0.0])
    assert empty.shape == (0, 4)
