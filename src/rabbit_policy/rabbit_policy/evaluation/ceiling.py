"""The ceiling of each action family for push recovery: an oracle that knows the push.

How far could *any* policy acting through a given family of actions carry RABBIT through a
backward push? The oracle answers it open loop, per case: classic HZD walks at a speed, a
push of known impulse lands at a known phase of a step (as the push margin places it:
:func:`~rabbit_policy.evaluation.robustness.phase_times`), and CMA-ES searches the actions
of the ``blocks`` x ``block_ticks`` ms after the push directly; then classic takes over
again. A case is *reached* when one action sequence leaves the robot walking (no fall, no
stall) ``horizon`` s after the push, the push margin's rule. The impulse is raised on a
ladder until the search finds no survivor: the family's ceiling at that case.

The families (what a policy could set, and when it takes effect):

* ``a_blended``: today's residual, +-0.1 rad on the 20 free coefficients and +-20 N m s/rad
  on Kd over classic's gait, decided every 20 ticks and blended in over 0.2 of phase, a gait
  arriving at or after 0.6 of phase queued for the next touchdown (the shipped rules);
* ``b_at_once``: the same residual applied at once (no blend, no queue; the paper);
* ``c_within_stance``: +-0.3 rad on every coefficient at once, and a phase that keeps moving
  in time while the hip stalls (``ControllerConfig.min_phase_rate`` per block, 0-4 1/s);
* ``d_gains``: Kp in 1000-6000 N m/rad and Kd in 0-300 N m s/rad per block, classic's gait;
* ``e_step_length``: +-0.1 rad on the posture rows only (row 0 and the impact-tied row 5:
  where a step starts and lands), under today's rules.

These are open-loop answers to one known push: they show what a family can reach, not that
a feedback policy finds it; and CMA-ES with a few hundred rollouts finds a lower bound of
the true ceiling. Everything runs on the one closed loop (:mod:`rabbit_policy.experiment`).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from rabbit_hzd_controller.alpha import N_FREE, expand_alpha, reduce_alpha
from rabbit_hzd_controller.controller import ControllerConfig
from rabbit_policy.experiment.loop import ClosedLoop
from rabbit_policy.experiment.scenario import Push, Scenario
from rabbit_policy.runtime.policies import GaitCommand, Policy, read_only_memo
from rabbit_policy.spec.make import make_policy
from rabbit_policy.runtime.speed_window import Observation

AT_ONCE = {"within_step_blend": 0.0, "within_step_until": 1.0, "blend_phase": 0.0}
"""Controller settings under which a gait applies from the next tick (no blend, no queue)."""


@dataclass(frozen=True)
class Family:
    """One action family: ``low``/``high`` bound its parameters per block; ``kind`` says what
    they mean (``residual``: offsets on the 20 free coefficients (rad) then Kd (N m s/rad);
    ``posture``: offsets on row 0's 4 coefficients (rad); ``gains``: Kp, Kd;
    ``residual_phase``: a residual then ``min_phase_rate`` (1/s)); ``controller``: the
    controller settings from the push on (``AT_ONCE`` or none: today's)."""

    name: str
    kind: str
    low: tuple[float, ...]
    high: tuple[float, ...]
    controller: tuple[tuple[str, float], ...] = ()
    description: str = ""

    @property
    def dims(self) -> int:
        return len(self.low)


def _family(name: str, kind: str, low, high, at_once: bool, description: str) -> Family:
    return Family(name, kind, tuple(float(v) for v in low), tuple(float(v) for v in high),
                  tuple(AT_ONCE.items()) if at_once else (), description)


_RES = 0.1
FAMILIES = {f.name: f for f in (
    _family("a_blended", "residual", [-_RES] * N_FREE + [-20.0], [_RES] * N_FREE + [20.0], False,
            "+-0.1 rad residual and +-20 Kd on classic, blended, queued from 0.6 of phase (today's)"),
    _family("b_at_once", "residual", [-_RES] * N_FREE + [-20.0], [_RES] * N_FREE + [20.0], True,
            "the same residual applied at once: no blend, no queue (the paper)"),
    _family("c_within_stance", "residual_phase", [-0.3] * N_FREE + [-20.0, 0.0], [0.3] * N_FREE + [20.0, 4.0], True,
            "+-0.3 rad on every coefficient at once, and a phase that moves at least 0-4 1/s in time"),
    _family("d_gains", "gains", [1000.0, 0.0], [6000.0, 300.0], False,
            "Kp 1000-6000 N m/rad and Kd 0-300 N m s/rad per block on classic's gait"),
    _family("e_step_length", "posture", [-_RES] * 4, [_RES] * 4, False,
            "+-0.1 rad on the posture rows (where a step starts and lands), today's rules"),
)}


@dataclass(frozen=True)
class CeilingConfig:
    """The oracle's search (times s, impulses N s).

    blocks, block_ticks: the actions after the push, piecewise constant over ``blocks``
        blocks of ``block_ticks`` 1 ms ticks; then classic alone.
    budget, popsize, sigma: CMA-ES rollouts per impulse, population, initial step (in
        units of each parameter's half range).
    horizon: survival is no fall and no stall this long after the push (the margin's).
    settle, push_duration: as the push margin (a push on the first step after ``settle``).
    """

    blocks: int = 5
    block_ticks: int = 200
    budget: int = 160
    popsize: int = 16
    sigma: float = 0.4
    horizon: float = 5.0
    settle: float = 3.0
    push_duration: float = 0.1
    seed: int = 1

    def __post_init__(self) -> None:
        for name in ("blocks", "block_ticks", "budget", "popsize"):
            value = getattr(self, name)
            if not (isinstance(value, int) and value >= 1):
                raise ValueError(f"CeilingConfig.{name} must be a whole number >= 1, got {value!r}")
        if not (0.0 < self.sigma <= 1.0 and self.horizon > 0.0 and self.settle > 0.0 and self.push_duration > 0.0):
            raise ValueError("CeilingConfig: sigma in (0, 1], horizon, settle and push_duration > 0")


class OracleGaits:
    """Classic HZD's gait plus whatever the oracle sets now (``offset``: a residual on the 20
    free coefficients and Kd, or None; ``kd``: a Kd that overrides). Decides when classic
    does (its ``decision_period``)."""

    def __init__(self, classic: Policy) -> None:
        self.classic = classic
        self.name = "oracle"
        self.decision_period = classic.decision_period
        self.decision_window = classic.decision_window
        self.offset: np.ndarray | None = None
        self.kd: float | None = None
        config = ControllerConfig()
        self._low = np.array([config.knee_coefficient_range[0] if i % 2 else config.hip_coefficient_range[0]
                              for i in range(N_FREE)])
        self._high = np.array([config.knee_coefficient_range[1] if i % 2 else config.hip_coefficient_range[1]
                               for i in range(N_FREE)])

    def act(self, observation: Observation) -> GaitCommand:
        command = self.classic.act(observation)
        kd = command.kd if self.kd is None else self.kd
        if self.offset is None:
            return GaitCommand(command.alpha, kd)
        free = np.clip(reduce_alpha(command.alpha) + self.offset[:N_FREE], self._low, self._high)
        kd = float(np.clip(kd + self.offset[N_FREE], 0.0, ControllerConfig().max_kd))
        return GaitCommand(tuple(float(v) for v in expand_alpha(free)), kd)


def clone_loop(loop: ClosedLoop) -> ClosedLoop:
    """An independent copy of a running loop (simulator, controller, policy, records) that
    goes on exactly as the original would; the compiled model is shared."""
    memo = {id(loop.model): loop.model, **read_only_memo(loop.policy)}  # read-only: shared
    new = copy.deepcopy(loop, memo)
    new._bind()  # views of the copy's MjData
    return new


@dataclass
class Case:
    """A loop stopped at the tick the push starts, and what the rollouts need."""

    loop: ClosedLoop
    push_tick: int
    end_tick: int


def prepare(speed: float, impulse: float, config: CeilingConfig, push_time: float) -> Case:
    """Classic HZD walking at ``speed`` m/s, stopped at ``push_time`` s, where a push of
    ``impulse`` N s (signed: negative backward) starts."""
    oracle = OracleGaits(make_policy("classic"))
    push = Push(push_time, impulse / config.push_duration, config.push_duration)
    loop = ClosedLoop(Scenario.constant(speed, pushes=(push,)), oracle)
    dt = loop.model.opt.timestep
    push_tick = int(round(push_time / dt))
    if loop.run(max_ticks=push_tick):
        raise RuntimeError(f"classic HZD does not walk to the push at {speed} m/s")
    return Case(loop, push_tick, push_tick + int(round(config.horizon / dt)))


def _apply_block(loop: ClosedLoop, family: Family, params: np.ndarray, base: ControllerConfig) -> None:
    oracle: OracleGaits = loop.policy  # type: ignore[assignment]
    controller = loop.controller
    settings = dict(family.controller)
    if family.kind in ("residual", "residual_phase"):
        oracle.offset = params[:N_FREE + 1]
        if family.kind == "residual_phase":
            settings["min_phase_rate"] = float(params[N_FREE + 1])
    elif family.kind == "posture":
        offset = np.zeros(N_FREE + 1)
        offset[:4] = params
        oracle.offset = offset
    elif family.kind == "gains":
        settings["kp"] = float(params[0])
        oracle.kd = float(params[1])
        controller.set_kd(float(params[1]))
    else:
        raise ValueError(f"unknown family kind {family.kind!r}")
    controller.config = replace(base, **settings)


def rollout(case: Case, family: Family, params: np.ndarray | None, config: CeilingConfig) -> dict:
    """One try from ``case``: ``params`` (blocks x dims, physical units; None: classic
    alone) for the blocks after the push, then classic. Returns ``survived``, the
    touchdowns after the push and the time (s) walked after it."""
    loop = clone_loop(case.loop)
    base = loop.controller.config
    steps_before = len(loop.touchdowns)
    failed = False
    if params is not None:
        for block in params:
            _apply_block(loop, family, block, base)
            if loop.run(max_ticks=config.block_ticks):
                failed = True
                break
        oracle: OracleGaits = loop.policy  # type: ignore[assignment]
        oracle.offset, oracle.kd = None, None
        loop.controller.config = base
    if not failed:
        loop.run(max_ticks=max(case.end_tick - loop.ticks, 0))
    dt = loop.model.opt.timestep
    walked = (loop.ticks - case.push_tick) * dt
    return {"survived": not loop.failed, "touchdowns": len(loop.touchdowns) - steps_before, "walked_s": walked}


def _fitness(outcome: dict, horizon: float) -> float:
    """What CMA-ES minimises: survival first, then steps taken, then time walked."""
    if outcome["survived"]:
        return -1000.0
    return -(outcome["touchdowns"] + outcome["walked_s"] / horizon)


def search(case: Case, family: Family, config: CeilingConfig, seed: int) -> dict:
    """CMA-ES over the blocks' parameters (normalised to [-1, 1]) until a survivor or the
    budget; returns ``found``, the rollouts used and the survivor's parameters if any."""
    import cma

    low, high = np.array(family.low), np.array(family.high)
    mid, half = 0.5 * (low + high), 0.5 * (high - low)
    zero = np.clip(np.zeros_like(mid), low, high)  # start at classic: no residual (gains: mid)
    x0 = np.tile(((zero - mid) / half) if family.kind != "gains" else np.zeros_like(mid), config.blocks)
    es = cma.CMAEvolutionStrategy(x0, config.sigma, {"popsize": config.popsize, "bounds": [-1.0, 1.0],
                                                     "seed": seed, "verbose": -9})
    used, best = 0, float("inf")
    while used < config.budget:
        xs = es.ask()
        scores = []
        for x in xs:
            params = (mid + half * np.asarray(x).reshape(config.blocks, family.dims))
            outcome = rollout(case, family, params, config)
            used += 1
            if outcome["survived"]:
                return {"found": True, "rollouts": used, "params": params.round(5).tolist()}
            scores.append(_fitness(outcome, config.horizon))
        best = min(best, min(scores))
        es.tell(xs, scores)
    return {"found": False, "rollouts": used, "best_fitness": best}


def ceiling(speed: float, phase: float, push_time: float, family: Family, impulses: list[float],
            config: CeilingConfig, log: Callable[[str], None] = lambda _: None) -> dict:
    """Backward-push ladder for one case: for each impulse (N s, magnitudes, increasing),
    classic alone first, then the oracle's search; stops at the first impulse nothing
    survives. Returns the ladder and ``reached_Ns`` (the largest impulse survived, 0 if
    none)."""
    ladder, reached = [], 0.0
    for k, impulse in enumerate(impulses):
        case = prepare(speed, -impulse, config, push_time)
        classic = rollout(case, family, None, config)["survived"]
        found = {"found": True, "rollouts": 0} if classic else search(case, family, config, config.seed + k)
        ladder.append({"impulse_Ns": impulse, "classic_survives": classic, **found})
        log(f"{family.name} v={speed} phase={phase} {impulse} N s: "
            f"{'classic' if classic else ('found' if found['found'] else 'none')} ({found['rollouts']} rollouts)")
        if not found["found"]:
            break
        reached = impulse
    return {"speed": speed, "phase": phase, "family": family.name, "reached_Ns": reached, "ladder": ladder}


def ladder(classic_margin: float, factors: tuple[float, ...]) -> list[float]:
    """The impulses (N s, whole) tried for a speed: ``factors`` x classic's margin there,
    rounded up, without repeats."""
    rungs = sorted({float(np.ceil(f * classic_margin - 1e-9)) for f in factors})
    return [r for r in rungs if r > 0]


def summarize(rows: list[dict]) -> list[dict]:
    """Per family and speed, over the phases tried: the ceiling (the smallest impulse
    reached over the phases: what a margin over every phase could be at most), the phases
    that bind it and the phases tried."""
    table: dict[tuple[str, float], dict] = {}
    for row in rows:
        key = (row["family"], row["speed"])
        entry = table.setdefault(key, {"family": row["family"], "speed": row["speed"], "ceiling_Ns": None,
                                       "binding_phases": [], "phases": 0})
        entry["phases"] += 1
        reached = row["reached_Ns"]
        if entry["ceiling_Ns"] is None or reached < entry["ceiling_Ns"]:
            entry["ceiling_Ns"], entry["binding_phases"] = reached, [row["phase"]]
        elif reached == entry["ceiling_Ns"]:
            entry["binding_phases"].append(row["phase"])
    return sorted(table.values(), key=lambda e: (e["family"], e["speed"]))
