"""The policy network's forward pass without torch: what deciding needs, so ``policy_node``
and the loops run a learned controller without importing torch. Training keeps the torch
network (:mod:`.network`, :class:`~.network.HZDPolicyNet`); this is its arithmetic: tanh
hidden layers, the last layer mapped onto the action bounds by ``output`` (``sigmoid``:
ours, ES and PPO; ``clip``: a Gaussian policy's mean clipped to [-1, 1], stable-baselines3's
PPO; ``tanh``: a squashed Gaussian, SB3's SAC), computed in a fixed order in float64
(:func:`.fixed_order.mlp`), so a decision has the same bits on every CPU."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rabbit_policy.runtime import fixed_order
from rabbit_policy.runtime.speed_window import Observation

OUTPUTS = ("sigmoid", "clip", "tanh")
"""The output maps, in :mod:`.fixed_order`'s numbering (SIGMOID, CLIP, TANH)."""


def _frozen(values) -> np.ndarray:
    a = np.array(values, dtype=np.float32)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class NetworkForward:
    """A network's forward pass, for deciding (torch stays for training): the arithmetic of
    :meth:`HZDPolicyNet.forward` on the same float32 weights, summed in float64 in a fixed
    order (:func:`.fixed_order.mlp`): equal to torch's float32 within its rounding (tested to
    1e-6 of each output's range) and the same bits on every CPU. A snapshot: build another
    after the weights change (:meth:`of`)."""

    weights: tuple[np.ndarray, ...]
    biases: tuple[np.ndarray, ...]
    offset: np.ndarray
    scale: np.ndarray
    low: np.ndarray
    high: np.ndarray
    output: str

    def __post_init__(self) -> None:
        if self.output not in OUTPUTS:
            raise ValueError(f"output must be one of {OUTPUTS}, got {self.output!r}")
        if len(self.weights) != len(self.biases) or not self.weights:
            raise ValueError("a network needs as many bias vectors as weight matrices, at least one")
        width = self.offset.shape[0]
        for w, b in zip(self.weights, self.biases):
            if w.ndim != 2 or w.shape[1] != width or b.shape != (w.shape[0],):
                raise ValueError(f"layer shapes do not chain: {w.shape} after {width} inputs, bias {b.shape}")
            width = w.shape[0]
        if not (self.scale.shape == self.offset.shape and self.low.shape == self.high.shape == (width,)):
            raise ValueError("input offset/scale and action bounds must match the first and last layers")
        params, shapes = fixed_order.pack_layers(self.weights, self.biases)
        offset, scale, low, high = (np.asarray(a, dtype=np.float64) for a in (self.offset, self.scale, self.low, self.high))
        object.__setattr__(self, "_network", (offset, scale, params, shapes, OUTPUTS.index(self.output)))
        object.__setattr__(self, "_bounds", (low, high - low))

    @classmethod
    def from_arrays(cls, weights, biases, offset, scale, low, high, output: str) -> "NetworkForward":
        """From plain arrays (a spec's weights file and its numbers), stored read-only float32."""
        return cls(tuple(_frozen(w) for w in weights), tuple(_frozen(b) for b in biases), _frozen(offset),
                   _frozen(scale), _frozen(low), _frozen(high), output)

    @classmethod
    def of(cls, net) -> "NetworkForward":
        """The forward pass of a torch ``HZDPolicyNet``'s current weights."""
        layers = [m for m in net.body if hasattr(m, "weight")]

        def array(t) -> np.ndarray:
            return t.detach().numpy()

        return cls.from_arrays([array(m.weight) for m in layers], [array(m.bias) for m in layers], array(net.offset),
                               array(net.scale), array(net.low), array(net.high), net.output)

    @property
    def inputs(self) -> int:
        return int(self.offset.shape[0])

    @property
    def hidden(self) -> tuple[int, ...]:
        return tuple(int(w.shape[0]) for w in self.weights[:-1])

    def normalised(self, x: Observation | np.ndarray | tuple) -> np.ndarray:
        """The action in [-1, 1] (float32, as an agent in a [-1, 1] Box gives it) for an
        observation (or the network's whole input vector, taken as float32 as the network is
        trained and an env observes it): :meth:`physical` of it is this network's output, bit for bit."""
        if isinstance(x, Observation):
            x = x.as_tuple()
        return fixed_order.mlp(np.asarray(x, dtype=np.float32).astype(np.float64), *self._network).astype(np.float32)

    def physical(self, action) -> np.ndarray:
        """A normalised action (in [-1, 1], taken as float32) on the action bounds (physical
        units, float64): ``low + (high - low) * (1 + a) / 2``, element by element."""
        low, span = self._bounds
        return low + span * ((1.0 + np.asarray(action, dtype=np.float32).astype(np.float64)) / 2.0)

    def __call__(self, x: Observation | np.ndarray | tuple) -> np.ndarray:
        """One deterministic action (float64, physical units) for an observation (or the
        network's whole input vector): :meth:`physical` of :meth:`normalised`."""
        return self.physical(self.normalised(x))
