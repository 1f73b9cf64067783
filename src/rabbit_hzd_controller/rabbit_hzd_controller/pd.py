"""PD tracking law with torque saturation (the paper's adaptive PD, eq. u = Kp e + Kd de)."""

from __future__ import annotations


def saturate(value: float, limit: float) -> float:
    """Clamp ``value`` to ``[-limit, limit]``."""
    return limit if value > limit else -limit if value < -limit else value


def pd_torque(
    q_desired: float,
    dq_desired: float,
    q: float,
    dq: float,
    kp: float,
    kd: float,
    limit: float,
) -> float:
    """Joint torque (N m) ``Kp (q_d - q) + Kd (dq_d - dq)`` saturated to ``+-limit``.

    Angles in rad, rates in rad/s, ``kp`` in N m/rad, ``kd`` in N m s/rad.
    """
    return saturate(kp * (q_desired - q) + kd * (dq_desired - dq), limit)
