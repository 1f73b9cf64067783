"""Bezier identities and the paper's 20 <-> 24 coefficient expansion."""

import numpy as np
import pytest

from rabbit_hzd_controller.alpha import (
    N_ALPHA,
    N_FREE,
    alpha_matrix,
    alpha_vector,
    expand_alpha,
    impact_violation,
    reduce_alpha,
)
from rabbit_hzd_controller.bezier import bernstein, bezier, bezier_derivative, bezier_matrix

pytestmark = pytest.mark.unit

rng = np.random.default_rng(42)


@pytest.mark.parametrize("trial", range(5))
def test_end_points(trial):
    a = rng.normal(size=6)
    assert bezier(a, 0.0) == pytest.approx(a[0])
    assert bezier(a, 1.0) == pytest.approx(a[5])


@pytest.mark.parametrize("trial", range(5))
def test_end_derivatives(trial):
    a = rng.normal(size=6)
    assert bezier_derivative(a, 0.0) == pytest.approx(5 * (a[1] - a[0]))
    assert bezier_derivative(a, 1.0) == pytest.approx(5 * (a[5] - a[4]))


def test_derivative_matches_finite_differences():
    a = rng.normal(size=6)
    h = 1e-6
    for tau in np.linspace(0.05, 0.95, 19):
        fd = (bezier(a, tau + h) - bezier(a, tau - h)) / (2 * h)
        assert bezier_derivative(a, tau) == pytest.approx(fd, rel=1e-6, abs=1e-7)


def test_basis_is_a_partition_of_unity_and_matrix_agrees():
    taus = np.linspace(0, 1, 11)
    B = bezier_matrix(taus)
    np.testing.assert_allclose(B.sum(axis=1), 1.0)
    for i, tau in enumerate(taus):
        np.testing.assert_allclose(B[i], bernstein(tau))
    a = rng.normal(size=6)
    np.testing.assert_allclose(B @ a, [bezier(a, t) for t in taus])


def test_constant_coefficients_give_a_constant():
    assert bezier([0.3] * 6, 0.37) == pytest.approx(0.3)
    assert bezier_derivative([0.3] * 6, 0.37) == pytest.approx(0.0)


def test_expansion_satisfies_the_paper_equalities():
    free = rng.normal(size=N_FREE)
    a = expand_alpha(free)
    assert a.shape == (N_ALPHA,)
    one = lambda i: a[i - 1]  # noqa: E731  (the paper's 1-based indexing)
    assert one(1) == one(23)
    assert one(2) == one(24)
    assert one(3) == one(21)
    assert one(4) == one(22)
    np.testing.assert_array_equal(a[:N_FREE], free)
    assert impact_violation(a) == 0.0


def test_round_trip():
    free = rng.normal(size=N_FREE)
    np.testing.assert_array_equal(reduce_alpha(expand_alpha(free)), free)


def test_coefficient_major_layout():
    a = np.arange(24.0)
    m = alpha_matrix(a)
    assert m.shape == (6, 4)
    assert m[2, 3] == 2 * 4 + 3  # coefficient 2 of the swing knee
    np.testing.assert_array_equal(alpha_vector(m), a)


def test_reduce_rejects_inconsistent_alpha():
    a = expand_alpha(rng.normal(size=N_FREE))
    a[22] += 0.1
    with pytest.raises(ValueError, match="impact equalities"):
        reduce_alpha(a)


@pytest.mark.parametrize("size", [0, 19, 21, 24])
def test_expand_rejects_wrong_size(size):
    with pytest.raises(ValueError):
        expand_alpha(np.zeros(size))


@pytest.mark.parametrize("size", [20, 23, 25])
def test_reduce_rejects_wrong_size(size):
    with pytest.raises(ValueError):
        reduce_alpha(np.zeros(size))


def test_the_compiled_degree_5_bezier_is_the_general_one_bit_for_bit():
    """The law's compiled degree-5 curve (the blend's start reads it) is the general
    ``bezier``'s arithmetic in the same order, so a reference the controller publishes and
    the law's blend agree to the last bit."""
    from rabbit_hzd_controller import law

    gen = np.random.default_rng(7)
    g = np.zeros((3, law.SLOT_SIZE))
    for _ in range(200):
        g[law.ACTIVE, :24] = gen.normal(size=24)
        t = float(gen.uniform(0.0, 1.0))
        for j in range(4):
            coeffs = g[law.ACTIVE, 6 * j:6 * j + 6].tolist()
            assert law.bezier5(g, law.ACTIVE, j, t) == bezier(coeffs, t)
            assert law.bezier5_derivative(g, law.ACTIVE, j, t) == bezier_derivative(coeffs, t)
