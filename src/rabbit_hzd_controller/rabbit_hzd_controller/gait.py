"""A periodic HZD gait: Bezier coefficients plus PD gains, with its design figures.

Gaits are stored as JSON (one file per gait); the classic gait library in
``rabbit_policy`` ships a set of them as package data.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from math import isfinite
from pathlib import Path
from typing import Any

import numpy as np

from .alpha import N_ALPHA, expand_alpha, reduce_alpha
from .kinematics import LegGeometry
from .phase import PhaseBounds, end_of_step_pitch, phase_bounds_from_alpha


@dataclass(frozen=True)
class Gait:
    """One periodic gait.

    alpha: the 24 Bezier coefficients (rad), coefficient-major, see :mod:`.alpha`.
    kd: derivative gain (N m s/rad). kp: proportional gain (N m/rad).
    speed: design average forward speed (m/s).
    step_length (m), step_period (s), cost (the optimizer's objective, see
    ``rabbit_policy.gait_design.optimization``) and ``info`` (anything else worth keeping:
    measured figures, solver statistics) describe how it walked when it was made.
    """

    alpha: tuple[float, ...]
    kd: float
    kp: float
    speed: float
    step_length: float = float("nan")
    step_period: float = float("nan")
    cost: float = float("nan")
    info: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        alpha = tuple(float(a) for a in self.alpha)
        if len(alpha) != N_ALPHA or not all(isfinite(a) for a in alpha):
            raise ValueError(f"Gait.alpha needs {N_ALPHA} finite coefficients")
        object.__setattr__(self, "alpha", alpha)
        reduce_alpha(alpha, atol=1e-6)  # raises if the impact equalities do not hold

    @classmethod
    def from_free(cls, free: np.ndarray, **kwargs: Any) -> "Gait":
        """Build from the 20 free coefficients."""
        return cls(alpha=tuple(expand_alpha(free)), **kwargs)

    @property
    def free(self) -> np.ndarray:
        """The 20 free coefficients."""
        return reduce_alpha(self.alpha, atol=1e-6)

    def bounds(self, geometry: LegGeometry | None = None) -> PhaseBounds:
        """Phase bounds implied by alpha (see :func:`.phase.phase_bounds_from_alpha`)."""
        return phase_bounds_from_alpha(self.alpha, geometry or LegGeometry())

    def touchdown_pitch(self, geometry: LegGeometry | None = None) -> float:
        """Torso pitch at touchdown (rad)."""
        return end_of_step_pitch(self.alpha, geometry or LegGeometry())

    def to_dict(self) -> dict[str, Any]:
        return asdict(self) | {"alpha": list(self.alpha)}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "Gait":
        known = {k: data[k] for k in cls.__dataclass_fields__ if k in data}
        return cls(**known)

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2, allow_nan=True) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> "Gait":
        """The gait in a JSON file; ``ValueError`` naming the file if it holds no gait."""
        try:
            data = json.loads(Path(path).read_text())
            if not isinstance(data, dict):
                raise ValueError("a JSON object is needed")
            return cls.from_dict(data)
        except (TypeError, ValueError, KeyError) as exc:
            raise ValueError(f"{path} is not a gait file ({str(exc)[:160]})") from None
