"""Kinematic identities on seeded random inputs (eqs 1, 2)."""

from __future__ import annotations

import numpy as np
import pytest

from numba import njit

from rbstab.kinematics import (
    add,
    cross,
    dot,
    euler_rate_matrix,
    hat,
    matTvec,
    matvec,
    neg,
    quadratic_form,
    rotation_and_rate,
    rotation_matrix,
    scale,
    sub,
)


def _elementary(theta):
    t1, t2, t3 = theta
    c, s = np.cos, np.sin
    a1 = np.array([[1, 0, 0], [0, c(t1), -s(t1)], [0, s(t1), c(t1)]])
    a2 = np.array([[c(t2), 0, s(t2)], [0, 1, 0], [-s(t2), 0, c(t2)]])
    a3 = np.array([[c(t3), -s(t3), 0], [s(t3), c(t3), 0], [0, 0, 1]])
    return a1 @ a2 @ a3


def _random_angles(rng, n):
    theta = rng.uniform(-np.pi, np.pi, size=(n, 3))
    theta[:, 1] = rng.uniform(-1.4, 1.4, size=n)
    return theta


def test_rotation_matrix_is_the_product_of_the_papers_elementary_rotations(rng):
    theta = _random_angles(rng, 50)
    stacked = rotation_matrix(theta)
    for th, a in zip(theta, stacked):
        np.testing.assert_allclose(a, _elementary(th), atol=1e-14)
        np.testing.assert_allclose(rotation_matrix(th), a, atol=0)


def test_rotation_matrix_is_orthonormal_with_determinant_one(rng):
    a = rotation_matrix(_random_angles(rng, 200))
    np.testing.assert_allclose(a @ np.swapaxes(a, -1, -2), np.broadcast_to(np.eye(3), a.shape), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(a), 1.0, atol=1e-13)


def test_hat_is_the_cross_product(rng):
    r, w = rng.normal(size=(2, 100, 3))
    np.testing.assert_allclose(np.einsum("nij,nj->ni", hat(r), w), np.cross(r, w), atol=1e-14)
    np.testing.assert_allclose(hat(r) + np.swapaxes(hat(r), -1, -2), 0.0)


def test_euler_rate_matrix_satisfies_dA_dt_equals_A_hat_omega(rng):
    """Finite differences of A along theta_dot = B omega reproduce A hat(omega)."""
    theta = _random_angles(rng, 100)
    omega = rng.normal(scale=3.0, size=(100, 3))
    theta_dot = np.einsum("nij,nj->ni", euler_rate_matrix(theta), omega)
    h = 1e-6
    da = (rotation_matrix(theta + h * theta_dot) - rotation_matrix(theta - h * theta_dot)) / (2 * h)
    expected = rotation_matrix(theta) @ hat(omega)
    np.testing.assert_allclose(da, expected, atol=1e-7 * np.abs(theta_dot).max())


def test_the_papers_printed_B_violates_the_kinematic_identity(rng):
    """The paper prints row 2 of B as [s3/c2, c3/c2, 0]; documented as wrong in docs/physics.md."""
    theta = np.array([0.3, 0.7, -0.4])
    omega = np.array([1.0, -2.0, 0.5])
    b = euler_rate_matrix(theta).copy()
    b[1, :2] /= np.cos(theta[1])  # the printed middle row
    h = 1e-6
    theta_dot = b @ omega
    da = (rotation_matrix(theta + h * theta_dot) - rotation_matrix(theta - h * theta_dot)) / (2 * h)
    assert np.abs(da - rotation_matrix(theta) @ hat(omega)).max() > 1e-2


@pytest.mark.parametrize("fn", [rotation_matrix, euler_rate_matrix, hat])
def test_stacked_inputs_match_single_inputs(fn, rng):
    x = _random_angles(rng, 7).reshape(7, 3)
    stacked = fn(x)
    assert stacked.shape == (7, 3, 3)
    for xi, si in zip(x, stacked):
        np.testing.assert_array_equal(fn(xi), si)
    assert fn(x.reshape(7, 1, 3)).shape == (7, 1, 3, 3)


def test_rotation_and_rate_is_rotation_matrix_and_euler_rate_matrix(rng):
    theta = _random_angles(rng, 20)
    for th in (theta, theta[0], theta.reshape(4, 5, 3)):
        a, b = rotation_and_rate(th)
        np.testing.assert_array_equal(a, rotation_matrix(th))
        np.testing.assert_array_equal(b, euler_rate_matrix(th))


@njit
def _compiled_algebra(a, b, m):
    return (add(a, b), sub(a, b), neg(a), scale(2.5, a), dot(a, b), cross(a, b), matvec(m, a), matTvec(m, a),
            quadratic_form(a, m))


def test_compiled_vector_algebra_is_numpys(rng):
    """The compiled 3-vector helpers of the physics against numpy's own operations."""
    for _ in range(20):
        a, b = rng.normal(size=(2, 3))
        m = rng.normal(size=(3, 3))
        got = _compiled_algebra(tuple(a), tuple(b), m)
        expected = (a + b, a - b, -a, 2.5 * a, a @ b, np.cross(a, b), m @ a, m.T @ a, a @ m @ a)
        for g, e in zip(got, expected):
            np.testing.assert_allclose(np.array(g), e, rtol=1e-14, atol=1e-14)
