"""Warm start for HZD-RL training: fit the policy network to the classic gait library.

The network is trained (supervised, Adam, mean squared error in action units scaled by
the bounds) to output the library gait interpolated at the commanded speed, whatever the
measured speeds: a learned policy that starts as the classic HZD controller, from which
ES/PPO then learn the feedback the classic controller lacks. Deterministic for a seed.
"""

from __future__ import annotations

import numpy as np
import torch

from .gait_library import GaitLibrary
from .network import HZDPolicyNet


def library_targets(library: GaitLibrary, speeds: np.ndarray) -> np.ndarray:
    """(n, 21) actions: free coefficients + Kd of the interpolated library gait."""
    rows = []
    for v in speeds:
        gait = library.interpolate(float(v))
        rows.append(np.append(gait.free, gait.kd))
    return np.array(rows)


def warm_start(net: HZDPolicyNet, library: GaitLibrary, seed: int = 0, iterations: int = 3000,
               samples: int = 512, speed_spread: float = 0.3, lr: float = 3e-3) -> float:
    """Fit ``net`` in place; returns the final mean squared error in normalised units
    (action range = 1)."""
    rng = np.random.default_rng(seed)
    torch.manual_seed(seed)
    lo, hi = library.speeds[0], library.speeds[-1]
    desired = rng.uniform(lo, hi, samples)
    measured = desired + rng.uniform(-speed_spread, speed_spread, samples)
    obs = torch.tensor(np.stack([desired, measured, desired - measured], axis=1), dtype=torch.float32)
    targets = torch.tensor(library_targets(library, desired), dtype=torch.float32)
    span = net.high - net.low
    optimiser = torch.optim.Adam(net.parameters(), lr=lr)
    loss = torch.tensor(0.0)
    for _ in range(iterations):
        optimiser.zero_grad()
        loss = (((net(obs) - targets) / span) ** 2).mean()
        loss.backward()
        optimiser.step()
    return float(loss.detach())
