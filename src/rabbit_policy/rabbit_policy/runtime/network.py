"""The HZD-RL policy network (paper, Fig. 3): 3 inputs -> three hidden layers of 12 ->
21 outputs (20 free Bezier coefficients + Kd), sigmoid output scaled to the action bounds.

Parameter count: 3*12+12 + 2*(12*12+12) + 12*21+21 = 633. The paper states 620, which is
the same network with 20 outputs (Kd not an output); its text makes Kd an output, which
we follow.

Inputs are normalised inside the network from physical units (m/s): the desired speed
is centred on the middle of [0.7, 1.5] m/s, and all three are divided by ``input_scale``,
so a checkpoint carries everything needed to run it.

``output`` says how the last layer maps onto the action bounds: ``sigmoid`` (ours, ES and
PPO), ``clip`` (a Gaussian policy's mean clipped to [-1, 1], stable-baselines3's PPO) or
``tanh`` (a squashed Gaussian, SB3's SAC); the last two come from ``scripts/train_sb3.py``,
which exports SB3's actor (the same 3 -> 12 -> 12 -> 12 -> 21 tanh body, raw inputs:
offset 0, scale 1) into this network, so ``policy_node`` and ``walk.py`` run it without SB3.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from rabbit_policy.runtime.body import BODY_OFFSET, BODY_SCALE
from rabbit_policy.runtime.forward import OUTPUTS, NetworkForward

__all__ = ["HZDPolicyNet", "NetworkForward", "PolicyCheckpoint", "input_normalisation", "parameter_count",
           "spec_network", "widen_inputs"]

HIDDEN = 12
N_INPUTS = 3
N_OUTPUTS = 21


class HZDPolicyNet(nn.Module):
    """obs (..., 3) in m/s -> action (..., 21) inside [low, high]."""

    def __init__(self, low: np.ndarray, high: np.ndarray, speed_centre: float = 1.1,
                 input_scale: float = 0.4, output: str = "sigmoid", inputs: int = N_INPUTS,
                 memory_limit: float = 0.2) -> None:
        """``inputs`` > 3: the paper's three then :mod:`.memory`'s (the integral, scaled by
        ``memory_limit``, and the last action, already in [-1, 1]), then :mod:`.body`'s
        (normalised by its ``BODY_OFFSET``/``BODY_SCALE``)."""
        super().__init__()
        if output not in OUTPUTS:
            raise ValueError(f"output must be one of {OUTPUTS}, got {output!r}")
        if inputs < N_INPUTS:
            raise ValueError(f"a policy network has at least {N_INPUTS} inputs, got {inputs}")
        self.output = output
        self.body = nn.Sequential(
            nn.Linear(inputs, HIDDEN), nn.Tanh(),
            nn.Linear(HIDDEN, HIDDEN), nn.Tanh(),
            nn.Linear(HIDDEN, HIDDEN), nn.Tanh(),
            nn.Linear(HIDDEN, N_OUTPUTS),
        )
        self.register_buffer("low", torch.as_tensor(low, dtype=torch.float64).float())
        self.register_buffer("high", torch.as_tensor(high, dtype=torch.float64).float())
        offset, scale = input_normalisation(inputs, speed_centre, input_scale, memory_limit)
        self.register_buffer("offset", torch.tensor(offset))
        self.register_buffer("scale", torch.tensor(scale))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        y = self.body((obs - self.offset) / self.scale)
        if self.output == "sigmoid":
            unit = torch.sigmoid(y)
        else:  # a normalised action in [-1, 1], as a Gymnasium env with a [-1, 1] Box takes it
            unit = (1.0 + (torch.clamp(y, -1.0, 1.0) if self.output == "clip" else torch.tanh(y))) / 2.0
        return self.low + (self.high - self.low) * unit


def input_normalisation(inputs: int, speed_centre: float = 1.1, input_scale: float = 0.4,
                        memory_limit: float = 0.2) -> tuple[list[float], list[float]]:
    """(offset, scale) of each of ``inputs`` inputs, in the order of :mod:`.memory`: the
    paper's three, the integral and the 21 last actions, the body state; the network sees
    (input - offset) / scale."""
    offset = [speed_centre, speed_centre, 0.0] + [0.0] * 22 + list(BODY_OFFSET)
    scale = [float(input_scale)] * N_INPUTS + [float(memory_limit)] + [1.0] * 21 + list(BODY_SCALE)
    if not (N_INPUTS <= inputs <= len(offset)):
        raise ValueError(f"a policy network has {N_INPUTS} to {len(offset)} inputs, got {inputs}")
    return offset[:inputs], scale[:inputs]


def widen_inputs(net: HZDPolicyNet, inputs: int, memory_limit: float = 0.2) -> HZDPolicyNet:
    """``net`` with ``inputs`` inputs whose new ones start with zero weights: the same outputs
    for any value of the new inputs (a warm start on the paper's three carried over)."""
    wide = HZDPolicyNet(net.low.numpy(), net.high.numpy(), output=net.output, inputs=inputs,
                        memory_limit=memory_limit)
    state = {k: v.clone() for k, v in net.state_dict().items() if k not in ("offset", "scale")}
    weight = torch.zeros(HIDDEN, inputs)
    weight[:, :net.body[0].in_features] = state["body.0.weight"]
    state["body.0.weight"] = weight
    state["offset"], state["scale"] = wide.offset.clone(), wide.scale.clone()
    state["offset"][:N_INPUTS], state["scale"][:N_INPUTS] = net.offset[:N_INPUTS], net.scale[:N_INPUTS]
    wide.load_state_dict(state)
    return wide


def spec_network(forward: NetworkForward) -> HZDPolicyNet:
    """The torch network with ``forward``'s weights, input normalisation, bounds and output (a
    controller spec's network, to train it): :meth:`NetworkForward.of` of it is ``forward``."""
    if forward.hidden != (HIDDEN,) * 3:
        raise ValueError(f"training takes the paper's three hidden layers of {HIDDEN}, the spec has {forward.hidden}")
    net = HZDPolicyNet(np.array(forward.low), np.array(forward.high), output=forward.output, inputs=forward.inputs)
    layers = [m for m in net.body if isinstance(m, nn.Linear)]
    state = net.state_dict()
    for layer_index, (w, b) in zip(range(0, 2 * len(layers), 2), zip(forward.weights, forward.biases)):
        state[f"body.{layer_index}.weight"] = torch.tensor(np.array(w))
        state[f"body.{layer_index}.bias"] = torch.tensor(np.array(b))
    state["offset"], state["scale"] = torch.tensor(np.array(forward.offset)), torch.tensor(np.array(forward.scale))
    net.load_state_dict(state)
    net.eval()
    return net


def parameter_count(net: nn.Module) -> int:
    """Trainable parameters."""
    return sum(p.numel() for p in net.parameters() if p.requires_grad)


@dataclass(frozen=True)
class PolicyCheckpoint:
    """What a trained policy file holds."""

    state_dict: dict
    low: np.ndarray
    high: np.ndarray
    info: dict

    def network(self) -> HZDPolicyNet:
        net = HZDPolicyNet(self.low, self.high, output=self.info.get("output", "sigmoid"),
                           inputs=int(self.state_dict["body.0.weight"].shape[1]))
        net.load_state_dict(self.state_dict)
        net.eval()
        return net

    def save(self, path: str | Path) -> None:
        torch.save({"state_dict": self.state_dict, "low": self.low.tolist(), "high": self.high.tolist(),
                    "info": self.info}, Path(path))

    @classmethod
    def load(cls, path: str | Path) -> "PolicyCheckpoint":
        data = torch.load(Path(path), map_location="cpu", weights_only=True)
        return cls(data["state_dict"], np.array(data["low"]), np.array(data["high"]), data.get("info", {}))
