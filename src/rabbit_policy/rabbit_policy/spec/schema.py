"""A controller spec: one versioned, human-readable document that names every stage of a
controller in order and every constant it uses (ROS-free, no torch). Read by
:func:`load_spec`, written by :func:`dump_spec`, assembled by
:func:`rabbit_policy.spec.build`. Stages, in the order a decision runs them:

1. ``gait_library``: the library the gaits come from (``packaged`` or a directory beside the
   spec, checked by its content hash) and how a speed picks a gait (``mode``);
2. ``decision``: when the policy decides (every ``period_ticks`` control ticks of 1 ms; 0:
   once per step, at the touchdown) and its moving-average window;
3. ``speed_integral``: the integral of the mean speed error with every rule it runs by (its
   bound, gate, windup decay, feed-forward table), or null: the runtime's own
   :class:`~rabbit_policy.runtime.speed_integral.IntegralConfig`, read straight from its section;
4. ``network``: the HZD-RL network (architecture, input normalisation, action bounds, the
   residual it adds to the library's gait; its weights in a weights-only file named by
   hash), or null;
5. ``blend``: the network's gaits blended in alpha before the rule acts (the runtime's own
   :class:`~rabbit_policy.runtime.alpha_blend.BlendConfig`), or null;
6. ``recovery_rule``: the push-recovery rule's constants (the runtime's own
   :class:`~rabbit_policy.runtime.recovery.RecoveryConfig`, read straight from its section), or
   null; ``overlay``: how it sits on a network's gait (the runtime's own
   :class:`~rabbit_policy.runtime.recovery.OverlayConfig`; whether the controller applies
   gaits at once follows from the ``controller`` section, whether the overlay blends the
   network's gaits from ``blend``), or null;
7. ``controller``: the 1 kHz HZD controller's settings this controller runs on (the runtime's own
   :class:`~rabbit_hzd_controller.controller.ControllerSettings`, every field) and the hash of
   the robot model whose geometry and tick they run with.

``provenance`` is free text for people (what made it, from which commit); it is not read.
A section that is a runtime class is read by the same strict loader as the spec's own:
every field a key, none absent but those the class names in ``OPTIONAL_KEYS`` (its code
defaults are never read for a spec). Every other key is required, none more is allowed: a
spec with an unknown or missing key, a value of the wrong kind, or a file whose hash differs
fails with one line (:class:`SpecError`).
"""

from __future__ import annotations

import math
import typing
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from rabbit_hzd_controller.controller import ControllerSettings
from rabbit_msgs_py.cli import yaml_problem
from rabbit_msgs_py.decision_ticks import check_ticks
from rabbit_policy.runtime.actions import RESIDUAL_BASES
from rabbit_policy.runtime.alpha_blend import BlendConfig
from rabbit_policy.runtime.forward import OUTPUTS
from rabbit_policy.runtime.recovery import OverlayConfig, RecoveryConfig
from rabbit_policy.runtime.speed_integral import IntegralConfig, decision_dt

SPEC_VERSION = 2
"""2: the ``controller`` section names every 1 kHz controller constant and the robot model (1: its blends alone)."""
KINDS = ("classic", "recovery", "learned")


class SpecError(ValueError):
    """A controller spec that cannot be built as written: one line saying where and why."""


def _number(value: float, name: str, low: float | None = None, high: float | None = None,
            above: bool = False) -> None:
    """``value`` finite and within [low, high] (``above``: strictly above ``low``), else a SpecError naming ``name``."""
    ok = math.isfinite(value) and (low is None or (value > low if above else value >= low)) and (
        high is None or value <= high)
    if not ok:
        where = (f"> {low:g}" if above else f">= {low:g}") if low is not None else ""
        where += (" and " if where and high is not None else "") + (f"<= {high:g}" if high is not None else "")
        raise SpecError(f"{name} must be a finite number{' ' + where if where else ''}, got {value!r}")


def _ordered(pair: tuple[float, float], name: str, low: float | None = None) -> None:
    """A (low, high) range: both finite (above ``low`` if given) and low < high."""
    for i, v in enumerate(pair):
        _number(v, f"{name}[{i}]", low, above=low is not None)
    if not pair[0] < pair[1]:
        raise SpecError(f"{name} must be ordered low < high, got {list(pair)}")


@dataclass(frozen=True)
class LibrarySpec:
    """``source``: ``packaged`` (rabbit_policy/gaits) or a directory, relative to the spec
    file; ``sha256``: of its gait files (:func:`rabbit_policy.spec.files.library_hash`);
    ``mode``: ``interpolate`` (the calibrated blend) or ``nearest``."""

    source: str
    sha256: str
    mode: str


@dataclass(frozen=True)
class DecisionSpec:
    """``period_ticks``: control ticks (1 ms) between decisions, 0 = once per step;
    ``window_ticks``: the longest moving-average window of the observation (ticks)."""

    period_ticks: int
    window_ticks: int

    def __post_init__(self) -> None:
        try:
            check_ticks(self.period_ticks, "decision.period_ticks", minimum=0)
            check_ticks(self.window_ticks, "decision.window_ticks")
        except ValueError as exc:
            raise SpecError(str(exc)) from None


@dataclass(frozen=True)
class ResidualSpec:
    """The network's output is a residual on a base gait: ``base`` (``classic``: the library's
    gait for v_d + gain * I; ``recovery``: the recovery rule's decision on the library, the
    spec's ``recovery_rule``; ``recovery_gated``: that, the residual scaled by the rule's
    weight), ``scale`` (21 numbers: the residual's bound per output, rad and N m s/rad),
    ``bounds_margin`` (rad: how far the sum's coefficients may leave the library's range;
    null: up to the controller's coefficient limits), ``kd_bounds`` (N m s/rad: the sum's Kd
    range)."""

    base: str
    scale: tuple[float, ...]
    bounds_margin: float | None
    kd_bounds: tuple[float, float]

    def __post_init__(self) -> None:
        if self.base not in RESIDUAL_BASES:
            raise SpecError(f"network.residual.base must be one of {RESIDUAL_BASES}, got {self.base!r}")
        for i, v in enumerate(self.scale):
            _number(v, f"network.residual.scale[{i}]", 0.0)
        if self.bounds_margin is not None:
            _number(self.bounds_margin, "network.residual.bounds_margin", 0.0)
        _ordered(self.kd_bounds, "network.residual.kd_bounds", 0.0)


@dataclass(frozen=True)
class WeightsSpec:
    """A weights-only file (.npz of float32 arrays) beside the spec, and its SHA-256."""

    file: str
    sha256: str


@dataclass(frozen=True)
class NetworkSpec:
    """The HZD-RL network: ``features`` (``paper``: v_d, mean v, mean error; ``memory``: and the
    integral and the last action; ``body``: and the body state), ``inputs``, ``hidden``
    (widths of the tanh layers), ``outputs`` (21: 20 free Bezier coefficients and Kd),
    ``output`` (how the last layer maps onto [low, high]: ``sigmoid``, ``clip``, ``tanh``),
    ``input_offset``/``input_scale`` (the network sees (x - offset) / scale), ``low``/``high``
    (the action's bounds, physical units), ``residual`` (null: the action is the gait
    itself), ``weights``."""

    features: str
    inputs: int
    hidden: tuple[int, ...]
    outputs: int
    output: str
    input_offset: tuple[float, ...]
    input_scale: tuple[float, ...]
    low: tuple[float, ...]
    high: tuple[float, ...]
    residual: ResidualSpec | None
    weights: WeightsSpec

    def __post_init__(self) -> None:
        if self.output not in OUTPUTS:
            raise SpecError(f"network.output must be one of {OUTPUTS}, got {self.output!r}")
        if self.inputs < 1 or self.outputs < 1 or not self.hidden or min(self.hidden) < 1:
            raise SpecError(f"network.inputs, outputs and hidden widths must be >= 1, got {self.inputs}, "
                            f"{self.outputs}, {list(self.hidden)}")
        for name, values, size in (("input_offset", self.input_offset, self.inputs),
                                   ("input_scale", self.input_scale, self.inputs),
                                   ("low", self.low, self.outputs), ("high", self.high, self.outputs)):
            if len(values) != size:
                raise SpecError(f"network.{name} needs {size} numbers (network.{'inputs' if size == self.inputs else 'outputs'}), "
                                f"got {len(values)}")
        for i, v in enumerate(self.input_offset):
            _number(v, f"network.input_offset[{i}]")
        for i, v in enumerate(self.input_scale):
            _number(v, f"network.input_scale[{i}]", 0.0, above=True)
        for i, (lo, hi) in enumerate(zip(self.low, self.high)):
            _number(lo, f"network.low[{i}]")
            _number(hi, f"network.high[{i}]")
            if not lo < hi:
                raise SpecError(f"network.low[{i}] ({lo!r}) must be below network.high[{i}] ({hi!r})")


@dataclass(frozen=True, kw_only=True)
class ControllerSection(ControllerSettings):
    """The ``controller`` section: the 1 kHz HZD controller's own settings class
    (:class:`~rabbit_hzd_controller.controller.ControllerSettings`, every field, checked by it)
    and ``model_sha256``, the robot model whose leg geometry and tick those run with
    (:func:`rabbit_sim.physics.model.model_sha256`): a spec made for another model is refused."""

    model_sha256: str

    def __post_init__(self) -> None:
        super().__post_init__()
        if not _is_sha256(self.model_sha256):
            raise SpecError(f"controller.model_sha256 must be 64 hex digits, got {self.model_sha256!r}")


def _is_sha256(text: str) -> bool:
    return isinstance(text, str) and len(text) == 64 and all(c in "0123456789abcdef" for c in text)


@dataclass(frozen=True)
class ControllerSpec:
    """One controller, every stage and constant (the module docstring)."""

    spec_version: int
    name: str
    kind: str
    gait_library: LibrarySpec
    decision: DecisionSpec
    speed_integral: IntegralConfig | None
    network: NetworkSpec | None
    blend: BlendConfig | None
    recovery_rule: RecoveryConfig | None
    overlay: OverlayConfig | None
    controller: ControllerSection
    provenance: dict = field(default_factory=dict)
    OPTIONAL_KEYS: typing.ClassVar[tuple[str, ...]] = ("provenance",)

    def __post_init__(self) -> None:
        if self.spec_version != SPEC_VERSION:
            raise SpecError(f"spec_version {self.spec_version} is not supported (this code reads {SPEC_VERSION})")
        if self.kind not in KINDS:
            raise SpecError(f"kind must be one of {KINDS}, got {self.kind!r}")
        if (self.kind == "learned") != (self.network is not None):
            raise SpecError("a learned spec has a network and only a learned one does")
        if self.kind == "learned" and self.gait_library.mode != "interpolate":
            raise SpecError(f"gait_library.mode {self.gait_library.mode!r}: a learned controller's gaits are the "
                            "calibrated blend (interpolate) with its residual; nearest is classic's")
        if (self.kind == "recovery") and self.recovery_rule is None:
            raise SpecError("a recovery spec needs its recovery_rule")
        if self.overlay is not None and (self.network is None or self.recovery_rule is None):
            raise SpecError("an overlay sits on a network's gaits: it needs network and recovery_rule")
        if self.blend is not None and self.overlay is None:
            raise SpecError("blend is an overlay's (the network's gaits blended before the rule)")
        residual = self.network.residual if self.network is not None else None
        on_rule = residual is not None and residual.base != "classic"
        if on_rule and self.recovery_rule is None:
            raise SpecError(f"a residual on base {residual.base} needs the recovery_rule it adds to")
        if self.recovery_rule is not None and self.kind == "learned" and self.overlay is None and not on_rule:
            raise SpecError("a learned spec with a recovery_rule needs its overlay or a residual on the rule")
        if self.recovery_rule is not None and self.decision.period_ticks < 1:
            raise SpecError("the recovery rule acts within the step: decision.period_ticks must be >= 1")
        if self.speed_integral is not None:
            expected = decision_dt(self.decision.period_ticks)
            if abs(self.speed_integral.dt - expected) > 1e-12:
                raise SpecError(f"speed_integral.dt ({self.speed_integral.dt!r} s) must be the time between decisions, "
                                f"{expected!r} s (decision.period_ticks {self.decision.period_ticks})")

    def to_dict(self) -> dict:
        """As written in the file (tuples as lists)."""
        return _plain(asdict(self))


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def parse_spec(data: Any) -> ControllerSpec:
    """A :class:`ControllerSpec` from a parsed document; :class:`SpecError` with one line
    for an unknown or missing key or a value of the wrong kind."""
    if isinstance(data, dict) and data.get("spec_version") == 1:
        raise SpecError("spec_version 1 names only the controller's blends: upgrade the file with "
                        "rabbit_policy.spec.convert.upgrade_spec(PATH) (it adds the values version 1 ran with)")
    return _parse(ControllerSpec, data, "spec")


def _parse(cls, data: Any, where: str):
    if not isinstance(data, dict):
        raise SpecError(f"{where} must be a mapping, got {type(data).__name__}")
    hints = typing.get_type_hints(cls)
    known = [f.name for f in fields(cls)]
    unknown = sorted(set(data) - set(known))
    if unknown:
        raise SpecError(f"unknown key {unknown[0]!r} in {where} (known: {', '.join(known)})")
    values = {}
    for f in fields(cls):
        if f.name not in data:
            if f.name in getattr(cls, "OPTIONAL_KEYS", ()):  # absent: the field's default
                continue
            raise SpecError(f"missing key {f.name!r} in {where}")
        values[f.name] = _value(hints[f.name], data[f.name], f"{where}.{f.name}")
    try:
        return cls(**values)
    except SpecError:
        raise
    except (TypeError, ValueError) as exc:
        raise SpecError(f"{where}: {exc}") from None


def _value(kind, value: Any, where: str):
    origin = typing.get_origin(kind)
    args = typing.get_args(kind)
    if origin in (typing.Union, getattr(__import__("types"), "UnionType", None)):
        if value is None and type(None) in args:
            return None
        (inner,) = [a for a in args if a is not type(None)]
        return _value(inner, value, where)
    if isinstance(kind, type) and hasattr(kind, "__dataclass_fields__"):
        return _parse(kind, value, where)
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise SpecError(f"{where} must be a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_value(args[0], v, f"{where}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise SpecError(f"{where} must hold {len(args)} values, got {len(value)}")
        return tuple(_value(a, v, f"{where}[{i}]") for i, (a, v) in enumerate(zip(args, value)))
    if kind is dict or origin is dict:
        if not isinstance(value, dict):
            raise SpecError(f"{where} must be a mapping, got {value!r}")
        return dict(value)
    if kind is bool:
        if not isinstance(value, bool):
            raise SpecError(f"{where} must be true or false, got {value!r}")
        return value
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise SpecError(f"{where} must be a whole number, got {value!r}")
        return value
    if kind is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise SpecError(f"{where} must be a finite number, got {value!r}")
        return float(value)
    if kind is str:
        if not isinstance(value, str):
            raise SpecError(f"{where} must be a string, got {value!r}")
        return value
    raise TypeError(f"no parser for {kind!r} at {where}")  # a schema bug, not a user's


def load_spec(path: str | Path) -> ControllerSpec:
    """Read and parse the spec file ``path`` (YAML or JSON); :class:`SpecError` with one line."""
    import yaml

    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise SpecError(f"cannot read controller spec {path}: {exc.strerror or exc}") from None
    except yaml.YAMLError as exc:
        raise SpecError(f"controller spec {path} is not YAML: {yaml_problem(exc)}") from None
    try:
        return parse_spec(data)
    except SpecError as exc:
        raise SpecError(f"controller spec {path}: {exc}") from None


def dump_spec(spec: ControllerSpec, path: str | Path, header: str = "") -> None:
    """Write ``spec`` as YAML (keys in the schema's order; ``header``: comment lines first)."""
    import yaml

    text = yaml.safe_dump(spec.to_dict(), sort_keys=False, default_flow_style=None, width=110)
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    Path(path).write_text("\n".join(lines) + ("\n" if lines else "") + text)
