"""The Poincaré tools recover known eigenvalues before they are trusted on RABBIT."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rabbit_policy.evaluation.poincare import (
    analyse_return_map,
    finite_difference_jacobian,
    regression_jacobian,
    section_crossing,
)

pytestmark = pytest.mark.unit


def test_linear_map_with_a_complex_pair_and_a_real_eigenvalue():
    # P(x) = c + A (x - c), A = R diag-blocks: eigenvalues 0.6 e^{+-0.5i} and -0.3
    c = np.array([1.0, -2.0, 0.5])
    block = 0.6 * np.array([[math.cos(0.5), -math.sin(0.5)], [math.sin(0.5), math.cos(0.5)]])
    a = np.zeros((3, 3))
    a[:2, :2], a[2, 2] = block, -0.3
    basis = np.array([[1.0, 0.2, 0.0], [0.3, 1.0, 0.1], [0.0, 0.4, 1.0]])  # not orthogonal
    a = basis @ a @ np.linalg.inv(basis)
    result = analyse_return_map(lambda x: c + a @ (x - c), np.zeros(3), delta=1e-3, iterations=200)
    assert result.residual < 1e-9 and np.allclose(result.fixed_point, c)
    assert result.magnitudes == pytest.approx([0.6, 0.6, 0.3], abs=1e-9)
    assert result.stable and result.to_dict()["largest"] == pytest.approx(0.6)


def test_unstable_fixed_point_of_the_henon_map_by_newton():
    a, b = 1.4, 0.3
    henon = lambda v: np.array([1.0 - a * v[0] ** 2 + v[1], b * v[0]])  # noqa: E731
    x = (-(1 - b) + math.sqrt((1 - b) ** 2 + 4 * a)) / (2 * a)  # the fixed point with x > 0
    result = analyse_return_map(henon, np.array([0.5, 0.1]), iterations=0, newton_steps=20)
    assert result.fixed_point == pytest.approx([x, b * x], abs=1e-9)
    expected = np.roots([1.0, 2 * a * x, -b])  # det(J - l I) = l^2 + 2 a x l - b
    assert sorted(result.magnitudes) == pytest.approx(sorted(np.abs(expected)), rel=1e-6)
    assert not result.stable


def test_limit_cycle_multiplier_of_a_sampled_flow_through_an_interpolated_section():
    """r' = r (1 - r^2), theta' = 2 pi: the unit circle is a limit cycle of period 1 with
    Floquet multiplier exp(-2) on the section y = 0, x > 0. Integrated with RK4 at a fixed
    step, as a simulator would, the crossing interpolated between samples."""

    def flow(s: np.ndarray) -> np.ndarray:
        x, y = s
        r2 = x * x + y * y
        return np.array([x * (1 - r2) - 2 * math.pi * y, y * (1 - r2) + 2 * math.pi * x])

    def rk4(s: np.ndarray, h: float) -> np.ndarray:
        k1 = flow(s)
        k2 = flow(s + 0.5 * h * k1)
        k3 = flow(s + 0.5 * h * k2)
        k4 = flow(s + h * k3)
        return s + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    def step(x: np.ndarray) -> np.ndarray:  # section coordinate: x on the positive x axis
        s = np.array([x[0], 0.0])
        s = rk4(s, 1e-3)  # leave the section
        while True:
            nxt = rk4(s, 1e-3)
            if s[1] < 0.0 <= nxt[1] and nxt[0] > 0:
                return section_crossing(s[1], nxt[1], s, nxt)[:1]
            s = nxt

    result = analyse_return_map(step, np.array([0.7]), delta=1e-4, iterations=30)
    assert result.fixed_point[0] == pytest.approx(1.0, abs=1e-6)
    assert result.magnitudes[0] == pytest.approx(math.exp(-2.0), rel=1e-3)


def test_regression_jacobian_sees_through_sample_grain_jumps():
    """A linear map plus a square wave of +-1e-4 on a 1e-3 grain (as a 1 ms simulation
    sampling an event; zero mean slope): central differences across a jump are ruined, the
    regression over moderate perturbations recovers the eigenvalues."""
    a = np.array([[0.5, 0.2], [-0.1, 0.8]])
    grain = lambda v: 1e-4 * (-1.0) ** np.floor(v / 1e-3)  # noqa: E731  jumps at every 1e-3
    step = lambda v: a @ v + grain(v[::-1])  # noqa: E731
    expected = sorted(np.abs(np.linalg.eigvals(a)))
    x = np.array([0.01234, -0.00567])
    fd = np.linalg.eigvals(finite_difference_jacobian(step, x, 1e-7))
    on_a_jump = np.array([0.0130000042, 0.0065])  # x[0] +- 1e-5 crosses the jump at 0.013
    fd_jumpy = np.linalg.eigvals(finite_difference_jacobian(step, on_a_jump, 1e-5))
    assert sorted(np.abs(fd)) == pytest.approx(expected, abs=1e-6)  # lucky: no jump within +-1e-7
    assert max(np.abs(fd_jumpy)) > 1.5  # 2e-4 / 2e-5 = 10 added to J[1, 0]: looks unstable
    regression = regression_jacobian(step, x, 0.05, samples=400)
    assert sorted(np.abs(np.linalg.eigvals(regression))) == pytest.approx(expected, abs=0.02)
    assert np.allclose(regression_jacobian(lambda v: a @ v, x, 0.01), a)  # exact on a linear map


def test_bad_inputs_are_refused():
    with pytest.raises(ValueError, match="> 0"):
        finite_difference_jacobian(lambda x: x, np.zeros(2), 0.0)
    with pytest.raises(ValueError, match="at least 2 samples"):
        regression_jacobian(lambda x: x, np.zeros(2), 0.1, samples=1)
    with pytest.raises(ValueError, match="no crossing"):
        section_crossing(1.0, 2.0, np.zeros(1), np.ones(1))
