"""Rotations: scipy as the third-party reference, round trips, slerp and smoothing properties."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from song.geometry import rotations as r

RNG = np.random.default_rng(7)
Q = r.quat_normalize(RNG.normal(size=(500, 4)))
TOL = 1e-12


def _scipy(q: np.ndarray) -> Rotation:
    return Rotation.from_quat(q[..., [1, 2, 3, 0]])


def test_matrix_matches_scipy():
    assert np.abs(r.quat_to_matrix(Q) - _scipy(Q).as_matrix()).max() < TOL


def test_matrix_to_quat_round_trip_and_positive():
    back = r.matrix_to_quat(r.quat_to_matrix(Q))
    assert np.all(back[:, 0] >= 0)
    assert np.abs(back - r.quat_positive(Q)).max() < 1e-12


def test_matrix_to_quat_near_pi_rotations():
    # 180° turns: the w-branch is singular, the other Shepperd branches must take over
    aa = np.array([[np.pi, 0, 0], [0, np.pi, 0], [0, 0, np.pi], [np.pi / np.sqrt(2), np.pi / np.sqrt(2), 0]])
    m = Rotation.from_rotvec(aa).as_matrix()
    assert np.abs(r.quat_to_matrix(r.matrix_to_quat(m)) - m).max() < 1e-12


def test_axis_angle_matches_scipy_and_round_trips():
    aa = r.quat_to_axis_angle(Q)
    assert np.abs(aa - _scipy(Q).as_rotvec()).max() < 1e-12
    assert np.abs(r.quat_positive(r.axis_angle_to_quat(aa)) - r.quat_positive(Q)).max() < 1e-12
    tiny = np.array([[1e-9, -2e-9, 3e-9], [0.0, 0.0, 0.0]])
    assert np.abs(r.quat_to_axis_angle(r.axis_angle_to_quat(tiny)) - tiny).max() < 1e-15
    assert np.abs(r.axis_angle_to_matrix(aa) - _scipy(Q).as_matrix()).max() < 1e-12
    assert np.abs(r.matrix_to_axis_angle(_scipy(Q).as_matrix()) - aa).max() < 1e-12


def test_sixd_round_trip_and_gram_schmidt():
    m = r.quat_to_matrix(Q)
    assert np.abs(r.sixd_to_matrix(r.matrix_to_6d(m)) - m).max() < 1e-12
    noisy = r.sixd_to_matrix(r.matrix_to_6d(m) + RNG.normal(scale=0.05, size=(500, 6)))
    assert np.abs(noisy @ np.swapaxes(noisy, -1, -2) - np.eye(3)).max() < 1e-12
    assert np.allclose(np.linalg.det(noisy), 1.0)


def test_mul_rotate_conj_match_matrices():
    a, b = Q[:250], Q[250:]
    assert np.abs(r.quat_to_matrix(r.quat_mul(a, b)) - r.quat_to_matrix(a) @ r.quat_to_matrix(b)).max() < 1e-12
    v = RNG.normal(size=(250, 3))
    assert np.abs(r.quat_rotate(a, v) - (r.quat_to_matrix(a) @ v[..., None])[..., 0]).max() < 1e-12
    ident = r.quat_mul(a, r.quat_conj(a))
    assert np.abs(r.quat_positive(ident) - r.quat_identity((250,))).max() < 1e-12


def test_torch_path_matches_numpy():
    torch = pytest.importorskip("torch")
    a, b = Q[:10], Q[10:20]
    v = RNG.normal(size=(10, 3))
    ta, tb, tv = torch.tensor(a), torch.tensor(b), torch.tensor(v)
    assert np.abs(r.quat_mul(ta, tb).numpy() - r.quat_mul(a, b)).max() < 1e-12
    assert np.abs(r.quat_to_matrix(ta).numpy() - r.quat_to_matrix(a)).max() < 1e-12
    assert np.abs(r.quat_rotate(ta, tv).numpy() - r.quat_rotate(a, v)).max() < 1e-12
    assert np.abs(r.quat_conj(ta).numpy() - r.quat_conj(a)).max() == 0


def test_axis_rotations_and_yaw():
    assert np.allclose(r.rot_z(np.pi / 2) @ [1, 0, 0], [0, 1, 0])
    assert np.allclose(r.rot_x(np.pi / 2) @ [0, 1, 0], [0, 0, 1])
    assert np.allclose(r.rot_y(np.pi / 2) @ [0, 0, 1], [1, 0, 0])
    yaws = np.linspace(-3, 3, 13)
    assert np.allclose(r.yaw_of_matrix(r.rot_z(yaws) @ r.rot_y(np.full(13, 0.3))), yaws)
    assert np.allclose(r.wrap_angle(np.array([np.pi, -np.pi, 3 * np.pi + 0.1])), [-np.pi, -np.pi, -np.pi + 0.1])


def test_wrap_angle_of_a_float_is_the_arrays_bit_for_bit() -> None:
    """A Python float takes the plain-float path; its result is the array path's, bit for bit."""
    rng = np.random.default_rng(0)
    angles = np.concatenate(
        [rng.normal(0, 10, 5000), rng.uniform(-1e4, 1e4, 5000), np.arange(-9, 10) * np.pi, [0.0, -0.0]]
    )
    scalar = np.array([r.wrap_angle(float(a)) for a in angles])
    assert all(type(r.wrap_angle(float(a))) is float for a in angles[:5])
    np.testing.assert_array_equal(scalar.view(np.int64), r.wrap_angle(angles).view(np.int64))


def test_slerp_endpoints_midpoint_and_shorter_arc():
    a, b = Q[:100], Q[100:200]
    assert np.abs(r.quat_positive(r.quat_slerp(a, b, 0.0)) - r.quat_positive(a)).max() < 1e-12
    assert r.quat_angle(r.quat_slerp(a, b, 1.0), b).max() < 1e-6
    mid = r.quat_slerp(a, b, 0.5)
    assert np.allclose(r.quat_angle(a, mid), r.quat_angle(mid, b), atol=1e-9)
    assert np.allclose(r.quat_angle(a, mid), 0.5 * r.quat_angle(a, b), atol=1e-9)
    # -b is the same rotation: slerp takes the shorter arc either way
    assert np.allclose(r.quat_angle(r.quat_slerp(a, -b, 0.3), r.quat_slerp(a, b, 0.3)), 0.0, atol=1e-6)
    # matches scipy's Slerp for one pair
    from scipy.spatial.transform import Slerp

    ref = Slerp([0, 1], _scipy(np.stack([a[0], b[0]])))([0.3]).as_quat()[0][[3, 0, 1, 2]]
    assert r.quat_angle(r.quat_slerp(a[0], b[0], 0.3), ref) < 1e-7


def test_quat_continuous_and_smoothing_ignore_sign_flips():
    yaw = np.linspace(0, 2.0, 60)
    q = r.quat_about_z(yaw)
    flipped = q * np.where(np.arange(60) % 3 == 0, -1.0, 1.0)[:, None]
    cont = r.quat_continuous(flipped)
    assert np.all(np.sum(cont[1:] * cont[:-1], axis=-1) > 0)
    smooth = r.smooth_quats(flipped, 2.0)
    # a constant-rate rotation is a fixed point of symmetric smoothing (away from the clamped ends)
    assert r.quat_angle(smooth[10:-10], q[10:-10]).max() < 1e-3
    noisy = r.quat_mul(q, r.axis_angle_to_quat(RNG.normal(scale=0.05, size=(60, 3))))
    assert r.quat_angle(r.smooth_quats(noisy, 2.0), q)[10:-10].mean() < r.quat_angle(noisy, q)[10:-10].mean()
    assert np.abs(r.smooth_quats(noisy, 0.0) - r.quat_continuous(noisy)).max() == 0


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-1, 1), min_size=12, max_size=12))
def test_property_composition_is_associative_and_orthonormal(values):
    raw = np.array(values).reshape(3, 4)
    if np.any(np.linalg.norm(raw, axis=1) < 1e-3):
        return
    a, b, c = r.quat_normalize(raw)
    left = r.quat_mul(r.quat_mul(a, b), c)
    right = r.quat_mul(a, r.quat_mul(b, c))
    assert np.allclose(left, right, atol=1e-12)
    m = r.quat_to_matrix(left)
    assert np.allclose(m @ m.T, np.eye(3), atol=1e-12)
    assert np.isclose(np.linalg.det(m), 1.0)


def test_compiled_conversions_equal_the_numpy_twins(monkeypatch: pytest.MonkeyPatch) -> None:
    """Large float64 batches go through numba kernels: same answers as the numpy forms (their twins)."""
    import song.geometry.rotations as rotations

    rng = np.random.default_rng(11)
    q = rng.normal(size=(300, 24, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    q[0, :4] = [[0, 1, 0, 0], [0, 0, 0, 1], [-1, 0, 0, 0], [0, 0, -1, 0]]  # each Shepperd branch, w < 0
    monkeypatch.setattr(rotations, "COMPILED_MIN", 10**12)
    twin_m = rotations.quat_to_matrix(q)
    twin_q = rotations.matrix_to_quat(twin_m)
    monkeypatch.setattr(rotations, "COMPILED_MIN", 256)
    np.testing.assert_allclose(rotations.quat_to_matrix(q), twin_m, rtol=0, atol=1e-15)
    np.testing.assert_allclose(rotations.matrix_to_quat(twin_m), twin_q, rtol=0, atol=1e-15)


def test_vector_norm_matches_numpy():
    rng = np.random.default_rng(5)
    for shape in [(4,), (10, 3), (6, 24, 4), (0, 3)]:
        v = rng.normal(size=shape)
        np.testing.assert_allclose(r.vector_norm(v), np.linalg.norm(v, axis=-1), rtol=1e-15, atol=0)
        assert r.vector_norm(v, keepdims=True).shape == (*shape[:-1], 1)
