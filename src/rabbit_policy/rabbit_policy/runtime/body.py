"""The body state inside the step (the learning issue's ablation row c): what a policy
deciding every N ticks sees of the robot besides the speeds, after Castillo et al. (IROS
2021, 2023: reduced-order observations of the body inside the step).

Five numbers, world frame, taken from the state the decision is made on:

| index | quantity | unit | normalised in the network by (offset, scale) |
|-------|----------|------|------------------------------------------------|
| 0 | torso pitch (positive: leaning forward) | rad | (0.0, 0.1) |
| 1 | torso pitch rate | rad/s | (0.0, 1.0) |
| 2 | gait phase tau of the stance step (0 at touchdown, 1 at the next) | 1 | (0.5, 0.5) |
| 3 | phase rate d tau / dt | 1/s | (2.0, 1.0) |
| 4 | horizontal hip velocity | m/s | (1.1, 0.4) |

The offsets and scales keep each input of a walk within about +-1 (measured on the
library's gaits at 0.7-1.5 m/s).
"""

from __future__ import annotations

from typing import Sequence

N_BODY = 5
BODY_OFFSET = (0.0, 0.0, 0.5, 2.0, 1.1)
BODY_SCALE = (0.1, 1.0, 0.5, 1.0, 0.4)


def body_state(qpos: Sequence[float], qvel: Sequence[float], tau: float, tau_rate: float) -> tuple[float, ...]:
    """The five body inputs from the planar state (``qpos``/``qvel`` in ``JOINT_NAMES``
    order: hip x, hip z, torso pitch, ...) and the controller's phase ``tau`` and its rate
    (1/s)."""
    return (float(qpos[2]), float(qvel[2]), float(tau), float(tau_rate), float(qvel[0]))
