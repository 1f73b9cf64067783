"""A shipped spec with a script's options written into it (``make_policy``'s: another gait
library, the library mode, another decision timing, classic's speed integral): the
variant is a spec too, so it is built like the shipped one, by :func:`~.build.build`."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from rabbit_msgs_py.decision_ticks import OWN, DecisionTiming
from rabbit_policy.runtime.classic import classic_integral
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.speed_integral import DEFAULT_OFFSET_LIMIT, decision_dt
from rabbit_policy.spec.files import library_dir, library_hash, packaged_spec
from rabbit_policy.spec.schema import ControllerSpec, LibrarySpec, SpecError, load_spec


def controller_spec(kind: str, gait_dir: str | Path | None = None, mode: str = "interpolate",
                    spec_file: str | Path | None = None, decision: DecisionTiming = OWN, speed_integral: float = 0.0,
                    offset_limit: float = DEFAULT_OFFSET_LIMIT) -> tuple[ControllerSpec, Path, str]:
    """(spec, the directory its files are named relative to, its file name) of controller
    ``kind``: the packaged spec, or ``spec_file``, with the options written in. Raises
    :class:`~.schema.SpecError` (a spec that is not one) or ``ValueError`` (options that do
    not go with it)."""
    path = Path(spec_file) if spec_file else packaged_spec(kind)
    spec = load_spec(path)
    base = path.resolve().parent
    if spec.kind != kind:
        raise SpecError(f"controller spec {path} is a {spec.kind} controller, not {kind}")
    if spec.kind == "learned":
        timed = _learned_timing(spec, decision)
        once = timed.overlay is None and spec.overlay is not None
        return timed, base, path.name + (" (no recovery rule: once per step)" if once else "")
    if gait_dir:
        directory = Path(gait_dir).resolve()
        try:
            library_hash(directory)
        except SpecError as exc:
            raise SpecError(f"cannot load the gait library: {exc}") from None
        spec = replace(spec, gait_library=LibrarySpec(str(directory), library_hash(directory), mode))
    else:
        spec = replace(spec, gait_library=replace(spec.gait_library, mode=mode))
    period = decision.resolve(spec.decision.period_ticks)
    if spec.kind == "recovery" and period < 1:
        raise ValueError("the recovery controller acts within the step: its decision period must be >= 1 tick")
    spec = replace(spec, decision=replace(spec.decision, period_ticks=period))
    if speed_integral:
        speeds = GaitLibrary.load(library_dir(spec.gait_library.source, base)).speed_range
        config = classic_integral(speed_integral, decision_dt(period), speeds, offset_limit)
        spec = replace(spec, speed_integral=config)
    return spec, base, path.name


def _learned_timing(spec: ControllerSpec, decision: DecisionTiming) -> ControllerSpec:
    """A learned spec deciding as ``decision`` says: once per step it runs without the
    recovery rule, which acts within the step (and the controller as classic's spec has it)."""
    period = decision.resolve(spec.decision.period_ticks)
    if period == spec.decision.period_ticks:
        return spec
    changes: dict = {"decision": replace(spec.decision, period_ticks=period)}
    if spec.speed_integral is not None:  # its dt is the time between decisions
        changes["speed_integral"] = replace(spec.speed_integral, dt=decision_dt(period))
    if period == 0 and spec.overlay is not None:
        classic = load_spec(packaged_spec("classic"))
        changes.update(overlay=None, blend=None, recovery_rule=None, controller=classic.controller)
    return replace(spec, **changes)
