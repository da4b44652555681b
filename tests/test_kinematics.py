"""Kinematic identities on seeded random inputs (eqs 1, 2)."""

from __future__ import annotations

import numpy as np
import pytest

from rbstab.kinematics import (
    ConstantMatrix,
    ConstantVector,
    add_columns,
    add_constant_columns,
    cross_columns,
    dot_constant_columns,
    euler_rate_matrix,
    from_columns,
    hat,
    matTvec,
    matTvec_columns,
    matvec,
    matvec_columns,
    quadratic_form,
    quadratic_form_columns,
    rate_matTvec_columns,
    rate_matvec_columns,
    rotation_and_rate,
    rotation_and_rate_columns,
    rotation_matrix,
    sub_columns,
    sub_constant_columns,
    to_columns,
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
        # the columns form holds the same matrices, entry by entry
        a_c, b_c = rotation_and_rate_columns(to_columns(th))
        np.testing.assert_array_equal(from_columns(a_c, th.shape[:-1]), a)
        np.testing.assert_array_equal(from_columns(b_c, th.shape[:-1]), b)


def _rows(x, m):
    """Columns-form vector -> stacked rows (m, 3) (or (3,) for one vector, m = None)."""
    return from_columns(x, () if m is None else (m,))


@pytest.mark.parametrize("m", [None, 1, 3, 7])
def test_columns_helpers_match_the_stacked_rows_helpers(m, rng):
    """One state (floats, m = None) and stacks; m = 3 guards against a constant 3-vector
    broadcast along the wrong axis."""
    n = 1 if m is None else m
    theta = _random_angles(rng, n)
    w, u = rng.normal(size=(2, n, 3))
    r, k = rng.normal(size=3), rng.normal(size=(3, 3))
    if m is None:
        theta, w, u = theta[0], w[0], u[0]
    cols = to_columns  # floats for one vector, (3, m) rows for a stack
    a_c, b_c = rotation_and_rate_columns(cols(theta))
    a, b = rotation_and_rate(theta)
    r_c = ConstantVector(r)
    close = dict(rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(_rows(matvec_columns(a_c, cols(w)), m), matvec(a, w), **close)
    np.testing.assert_allclose(_rows(matTvec_columns(a_c, cols(w)), m), matTvec(a, w), **close)
    np.testing.assert_allclose(_rows(matvec_columns(a_c, r_c), m), matvec(a, r), **close)
    np.testing.assert_allclose(_rows(rate_matvec_columns(b_c, cols(w)), m), matvec(b, w), **close)
    np.testing.assert_allclose(_rows(rate_matTvec_columns(b_c, cols(w)), m), matTvec(b, w), **close)
    np.testing.assert_allclose(_rows(ConstantMatrix(k).apply(cols(w)), m), matvec(k, w), **close)
    np.testing.assert_allclose(_rows(cross_columns(cols(w), cols(u)), m), np.cross(w, u), **close)
    np.testing.assert_allclose(_rows(cross_columns(cols(w), r_c), m), np.cross(w, r), **close)
    np.testing.assert_array_equal(_rows(add_columns(cols(w), r_c), m), w + r)
    np.testing.assert_array_equal(_rows(sub_columns(cols(w), cols(u)), m), w - u)
    np.testing.assert_array_equal(_rows(add_constant_columns(cols(w), ConstantVector((r[0], 0.0, r[2]))), m), w + r * [1, 0, 1])
    np.testing.assert_array_equal(_rows(sub_constant_columns(cols(w), ConstantVector(r)), m), w - r)
    w_c = cols(w)
    assert add_constant_columns(w_c, ConstantVector((0, 0, 0))) is w_c  # a zero constant costs nothing
    np.testing.assert_allclose(dot_constant_columns(cols(w), r_c), w @ r, **close)
    assert dot_constant_columns(cols(w), (0.0, 0.0, 0.0)) == 0.0
    np.testing.assert_allclose(quadratic_form_columns(cols(w), ConstantMatrix(k)), quadratic_form(w, k), **close)
    if m is None:  # one state: plain float arithmetic
        assert all(isinstance(c, float) for c in matvec_columns(a_c, cols(w)))


def test_constant_matrix_skips_zero_entries_and_diagonals_are_exact(rng):
    w = to_columns(rng.normal(size=(5, 3)))
    diag = ConstantMatrix(np.diag([2.0, 0.0, -3.0]))
    assert diag.diagonal == (2.0, 0.0, -3.0)
    np.testing.assert_array_equal(np.array(diag.apply(w)), np.diag([2.0, 0.0, -3.0]) @ w)
    sparse = np.array([[0.0, 1.5, 0.0], [0.0, 0.0, 0.0], [2.0, 0.0, -1.0]])
    op = ConstantMatrix(sparse)
    assert op.diagonal is None
    got = op.apply(w)
    np.testing.assert_array_equal(got[0], 1.5 * w[1])
    np.testing.assert_array_equal(got[1], np.zeros(5))
    np.testing.assert_array_equal(got[2], 2.0 * w[0] + -1.0 * w[2])
    with pytest.raises(ValueError, match="shape"):
        ConstantMatrix(np.eye(2))


def test_columns_of_a_stack_do_not_depend_on_the_other_states(rng):
    """Every columns operation is elementwise: a state's bits are the same alone (as
    floats) and in any stack."""
    theta = _random_angles(rng, 6)
    w = rng.normal(size=(6, 3))
    k = ConstantMatrix(rng.normal(size=(3, 3)))

    def chain(th, om, shape):
        a, b = rotation_and_rate_columns(to_columns(th))
        out = k.apply(cross_columns(matTvec_columns(a, rate_matvec_columns(b, to_columns(om))), to_columns(om)))
        return from_columns(out, shape)

    whole = chain(theta, w, (6,))
    part = chain(theta[2:5], w[2:5], (3,))
    alone = chain(theta[3], w[3], ())
    np.testing.assert_array_equal(part, whole[2:5])
    np.testing.assert_array_equal(alone, whole[3])


def test_to_columns_and_back_round_trip(rng):
    y = rng.normal(size=(2, 3, 5))
    yc = to_columns(y)
    assert yc.shape == (5, 6) and yc.flags.c_contiguous
    np.testing.assert_array_equal(yc[:, 4], y[1, 1])
    back = from_columns(yc, y.shape[:-1])
    assert back.flags.c_contiguous
    np.testing.assert_array_equal(back, y)
    one = to_columns(y[0, 0])
    assert isinstance(one, list) and all(isinstance(c, float) for c in one)
    np.testing.assert_array_equal(from_columns(one, ()), y[0, 0])
    m = rng.normal(size=(3, 3, 6))
    np.testing.assert_array_equal(from_columns(m, (2, 3))[1, 2], m[:, :, 5])
    # constant components (scalars) of a stack are broadcast
    np.testing.assert_array_equal(from_columns((np.arange(4.0), 0.0, 1.0), (4,))[:, 1:], [[0.0, 1.0]] * 4)
