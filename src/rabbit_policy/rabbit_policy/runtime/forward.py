"""The policy network's forward pass in numpy (no torch): what deciding needs, so
``policy_node`` and the loops run a learned controller without importing torch. Training
keeps the torch network (:mod:`.network`, :class:`~.network.HZDPolicyNet`); this is its
arithmetic: tanh hidden layers, the last layer mapped onto the action bounds by
``output`` (``sigmoid``: ours, ES and PPO; ``clip``: a Gaussian policy's mean clipped to
[-1, 1], stable-baselines3's PPO; ``tanh``: a squashed Gaussian, SB3's SAC)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rabbit_policy.runtime.speed_window import Observation

OUTPUTS = ("sigmoid", "clip", "tanh")


def _frozen(values) -> np.ndarray:
    a = np.array(values, dtype=np.float32)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class NetworkForward:
    """A network's forward pass in numpy, for deciding (torch stays for training): the same
    float32 arithmetic as :meth:`HZDPolicyNet.forward`, equal to it within float32 rounding
    (tested to 1e-6 of each output's range), at about a third of torch's cost per decision
    (``scripts/bench_train.py``'s ``forward_us``). A snapshot: build another after the
    weights change (:meth:`of`)."""

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

    def normalised(self, x) -> np.ndarray:
        """The action in [-1, 1] (float32) an agent in a [-1, 1] Box would give for this output:
        :meth:`physical` of it is this network's output (bit for bit for ``tanh`` and ``clip``)."""
        h = self._last_layer(x)
        if self.output == "sigmoid":
            return np.float32(2.0) / (np.float32(1.0) + np.exp(-h)) - np.float32(1.0)
        return np.clip(h, -1.0, 1.0) if self.output == "clip" else np.tanh(h)

    def physical(self, action) -> np.ndarray:
        """A normalised action (in [-1, 1]) on the action bounds (physical units, float)."""
        unit = (np.float32(1.0) + np.asarray(action, dtype=np.float32)) / np.float32(2.0)
        return (self.low + (self.high - self.low) * unit).astype(float)

    def _last_layer(self, x) -> np.ndarray:
        """The last layer's output (float32) before it is mapped onto the bounds."""
        if isinstance(x, Observation):
            x = x.as_tuple()
        h = (np.asarray(x, dtype=np.float32) - self.offset) / self.scale
        last = len(self.weights) - 1
        for i, (w, b) in enumerate(zip(self.weights, self.biases)):
            h = w @ h + b
            if i < last:
                h = np.tanh(h)
        return h

    @property
    def inputs(self) -> int:
        return int(self.offset.shape[0])

    @property
    def hidden(self) -> tuple[int, ...]:
        return tuple(int(w.shape[0]) for w in self.weights[:-1])

    def __call__(self, x: Observation | np.ndarray | tuple) -> np.ndarray:
        """One deterministic action (21 floats, physical units) for an observation (or the
        network's whole input vector)."""
        h = self._last_layer(x)
        if self.output == "sigmoid":
            unit = np.float32(1.0) / (np.float32(1.0) + np.exp(-h))
        else:
            unit = (np.float32(1.0) + (np.clip(h, -1.0, 1.0) if self.output == "clip" else np.tanh(h))) / np.float32(2.0)
        return (self.low + (self.high - self.low) * unit).astype(float)
