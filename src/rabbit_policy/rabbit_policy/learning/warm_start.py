"""Warm start for HZD-RL training: fit the policy network to the classic gait library.

The network is trained (supervised, Adam, mean squared error in action units scaled by
the bounds) to output what a classic gait-library controller would choose, so training
starts from classic HZD and ES/PPO learn what the library lacks (faster convergence after
a speed change, steady-state corrections). Three targets (:data:`WARM_STARTS`):

* ``nearest``: the library gait nearest to the commanded speed v_d, whatever the
  measured speeds: classic HZD as ``LibraryPolicy("nearest")`` runs it. At the library's
  speeds (0.7, 0.8, ..., 1.5 m/s) the fitted network sits mid-way along a flat stretch of
  the staircase and reproduces the gait; between them it blends across the stair's edge.
* ``interpolate``: the library gait blended at the commanded speed v_d, whatever the
  measured speeds (the network learns to ignore them).
* ``scheduled``: the gait *nearest* to v_d, except that its design speed never drops
  more than 0.2 m/s below the last step's mean hip speed — the usual rate limit when a
  gait library is scheduled, because switching from a fast gait straight to a much slower
  one falls (measured on ``RabbitHZD-v0``: 1.5 -> 1.0 or 1.2 m/s falls with the bare
  library, not with the limit; with the limit no episode of a 6 x 6 grid of speed
  changes fell). ``nearest`` rather than a blend: blends of neighbouring library gaits
  are not gaits in between (the 0.7/0.8 blends stall, 1.2/1.3 and 1.4/1.5 blends
  overshoot). Its staircase needs more fitting iterations.
* ``feedback``: the calibrated library blend (``interpolate``) for the command corrected
  by the measured error, v_d + ``feedback_gain`` * mean(v_d - v): classic HZD scheduled
  with a proportional speed feedback through the paper's third input. Measured with
  decisions every 20 ticks (ROS-free, 2026-11-23): gain 0.3 passed 59 of the 72 ordered
  changes where the library alone passed 51 (neither fell); 0.7 stalled at 0.7 m/s.

Deterministic for a seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.network import HZDPolicyNet


@dataclass(frozen=True)
class WarmStartConfig:
    """Target and fit: ``samples`` observations with v_d uniform over the library's speeds
    and the measured speed v_d +- ``speed_spread`` (m/s); ``iterations`` Adam steps.

    The third input, the mean speed error over the last step, equals v_d - measured only
    while the command is steady; in the step after a change it still holds the old
    command (error ~ 0 at 1.5 m/s just after 1.5 -> 0.7). A ``stale_error_fraction`` of
    the samples therefore take the error from an independent earlier command, uniform
    over the library's speeds, so the network also reproduces the target there (without
    them it extrapolated: after 1.5 -> 0.7 m/s it chose the 0.9 m/s gait's Kd for a step
    and the robot fell)."""

    target: str = "scheduled"
    iterations: int = 10000
    samples: int = 2048
    speed_spread: float = 0.9
    stale_error_fraction: float = 0.5
    max_decel: float = 0.2
    feedback_gain: float = 0.3
    lr: float = 3e-3


WARM_STARTS = {
    "scheduled": WarmStartConfig(),
    "nearest": WarmStartConfig(target="nearest"),
    "interpolate": WarmStartConfig(target="interpolate", iterations=3000, samples=512, speed_spread=0.3),
    "feedback": WarmStartConfig(target="feedback", iterations=6000, samples=2048, speed_spread=0.4,
                                stale_error_fraction=0.0),
}


def scheduled_speed(desired: float, measured: float, max_decel: float = 0.2) -> float:
    """Design speed (m/s) of the gait the scheduled classic controller picks: v_d, but at
    most ``max_decel`` below the measured speed."""
    return max(desired, measured - max_decel)


def library_targets(library: GaitLibrary, desired: np.ndarray, measured: np.ndarray | None = None,
                    target: str = "scheduled", max_decel: float = 0.2, errors: np.ndarray | None = None,
                    feedback_gain: float = 0.3) -> np.ndarray:
    """(n, 21) actions (free coefficients + Kd) the classic controller picks for each
    (commanded, measured) speed pair (``measured`` None: walking at the command; ``errors``
    the mean speed errors, None: desired - measured)."""
    measured = desired if measured is None else measured
    errors = desired - measured if errors is None else errors
    rows = []
    for v, m, e in zip(desired, measured, errors):
        if target == "feedback":
            gait = library.interpolate(float(v) + feedback_gain * float(e))
        elif target == "interpolate":
            gait = library.interpolate(float(v))
        elif target == "scheduled":
            gait = library.nearest(scheduled_speed(float(v), float(m), max_decel))
        elif target == "nearest":
            gait = library.nearest(float(v))
        else:
            raise ValueError(f"warm start target must be one of {sorted(WARM_STARTS)}, got {target!r}")
        rows.append(np.append(gait.free, gait.kd))
    return np.array(rows)


def warm_start(net: HZDPolicyNet, library: GaitLibrary, seed: int = 0,
               config: WarmStartConfig = WARM_STARTS["scheduled"]) -> float:
    """Fit ``net`` in place; returns the final mean squared error in normalised units
    (action range = 1)."""
    rng = np.random.default_rng(seed)
    torch.manual_seed(seed)
    lo, hi = library.speeds[0], library.speeds[-1]
    desired = rng.uniform(lo, hi, config.samples)
    measured = desired + rng.uniform(-config.speed_spread, config.speed_spread, config.samples)
    earlier = np.where(rng.random(config.samples) < config.stale_error_fraction,
                       rng.uniform(lo, hi, config.samples), desired)  # the command the error was measured against
    obs = torch.tensor(np.stack([desired, measured, earlier - measured], axis=1), dtype=torch.float32)
    targets = torch.tensor(library_targets(library, desired, measured, config.target, config.max_decel,
                                           earlier - measured, config.feedback_gain), dtype=torch.float32)
    span = net.high - net.low
    optimiser = torch.optim.Adam(net.parameters(), lr=config.lr)
    loss = torch.tensor(0.0)
    for _ in range(config.iterations):
        optimiser.zero_grad()
        loss = (((net(obs) - targets) / span) ** 2).mean()
        loss.backward()
        optimiser.step()
    return float(loss.detach())


def initial_network(low: np.ndarray, high: np.ndarray, library: GaitLibrary, seed: int,
                    start: str = "scheduled") -> tuple[HZDPolicyNet, float | None]:
    """The network a training run starts from: built after ``torch.manual_seed(seed)``,
    then warm-started with ``WARM_STARTS[start]`` (``"none"``: the random weights).
    Returns it and the warm start's final error (None without one). ``scripts/train.py``
    builds its network with it and ``scripts/ship_policy.py`` rebuilds the same one."""
    if start != "none" and start not in WARM_STARTS:
        raise ValueError(f"warm start must be one of {sorted(WARM_STARTS)} or 'none', got {start!r}")
    torch.manual_seed(seed)
    net = HZDPolicyNet(low, high)
    if start == "none":
        return net, None
    return net, warm_start(net, library, seed=seed, config=WARM_STARTS[start])


def zero_residual_network(low: np.ndarray, high: np.ndarray, inputs: int, seed: int) -> HZDPolicyNet:
    """The network a residual policy (``action="residual"``) starts from: random hidden
    layers (:func:`restart_network`) and a zero last layer with a tanh output on symmetric
    bounds, so its residual is exactly 0 — the classic controller — for any input."""
    if not np.allclose(np.asarray(low), -np.asarray(high)):
        raise ValueError("a residual's bounds are symmetric about 0")
    return restart_network(HZDPolicyNet(low, high, output="tanh", inputs=inputs), seed)


def restart_network(net: HZDPolicyNet, seed: int) -> HZDPolicyNet:
    """``net`` with its hidden layers drawn afresh and its last layer zero (weights and bias),
    in place: each hidden layer's weights and bias uniform in +-1/sqrt(fan-in) (PyTorch's
    default range) from NumPy's ``default_rng(seed)``, in layer order, rounded to float32.
    NumPy's generator gives the same bits on every CPU (torch's CPU kernels are compiled per
    instruction set), so a run that starts here is the same run everywhere."""
    rng = np.random.default_rng(seed)
    layers = [m for m in net.body if isinstance(m, torch.nn.Linear)]
    with torch.no_grad():
        for layer in layers[:-1]:
            bound = 1.0 / np.sqrt(layer.in_features)
            layer.weight.copy_(torch.from_numpy(rng.uniform(-bound, bound, tuple(layer.weight.shape)).astype(np.float32)))
            layer.bias.copy_(torch.from_numpy(rng.uniform(-bound, bound, tuple(layer.bias.shape)).astype(np.float32)))
        layers[-1].weight.zero_()
        layers[-1].bias.zero_()
    return net
