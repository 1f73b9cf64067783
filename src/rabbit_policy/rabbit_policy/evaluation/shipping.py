"""Whether a retrained learned controller ships over the one it was trained from.

The bar (the controller-spec issue): at least the start's acceptance checks, and better on
forward pushes and on the paper's ``large_backward`` scenario, while keeping its backward
pushes. Two measurements serve it:

* :func:`paper_scenarios`: the paper's three push scenarios as ``scripts/evaluate.py`` runs
  them (:data:`~.push_recovery.PUSH_SCENARIOS` at ``EvaluationConfig.push_speed`` for
  ``push_duration`` s): one outcome each.
* :func:`margin_grid`: single pushes scaled to classic HZD's own margin
  (:func:`~.push_recovery.classic_margin`) at speeds between the ones the margins were measured
  at, at evenly spaced phases of one step: forward ``forward`` x classic's forward margin,
  backward ``backward`` x its backward margin. A push is survived when the walk neither falls
  nor stalls within ``horizon`` s after it (:func:`~.robustness.push_survived`, the margin's
  rule). Far beyond the margin, survival flips with small changes of the gait, so the grid
  counts many pushes rather than judging a few.

:func:`verdict` compares a candidate's measurements with the start's, one reason per
line; :func:`screen_rank` orders candidates (eligible first, then forward, then backward).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from rabbit_policy.evaluation.experiments import EvaluationConfig
from rabbit_policy.evaluation.push_recovery import classic_margin, push_trial
from rabbit_policy.evaluation.robustness import MapFn, RobustnessConfig, phase_times, push_survived
from rabbit_policy.runtime.gait_command import Policy

DIRECTIONS = {"forward": 1, "backward": -1}


@dataclass(frozen=True)
class MarginGrid:
    """The push grid: ``speeds`` (m/s), multiples of classic's margin per direction,
    ``phases`` evenly spaced push phases of the first step after ``settle`` s, each push
    ``push_duration`` s long, survived when no fall or stall follows within ``horizon`` s."""

    speeds: tuple[float, ...] = (0.75, 0.95, 1.05, 1.25, 1.35)
    forward: tuple[float, ...] = (1.1, 1.4)
    backward: tuple[float, ...] = (1.5, 2.0)
    phases: int = 16
    settle: float = 3.0
    horizon: float = 5.0
    push_duration: float = 0.1

    def __post_init__(self) -> None:
        if not self.speeds or self.phases < 1 or self.horizon <= 0 or self.push_duration <= 0:
            raise ValueError("a margin grid needs speeds, >= 1 phase and a positive horizon and push duration")

    @classmethod
    def quick(cls) -> MarginGrid:
        """One speed, one multiple per direction, two phases (tests, the tiny preset)."""
        return cls(speeds=(1.05,), forward=(1.1,), backward=(1.5,), phases=2, horizon=2.0)

    def impulses(self, speed: float, direction: str) -> list[int]:
        """The grid's impulses (N s, signed, whole) at ``speed`` in ``direction``."""
        sign = DIRECTIONS[direction]
        return [sign * round(factor * classic_margin(speed, sign)) for factor in getattr(self, direction)]

    def pushes_per_direction(self, direction: str) -> int:
        return len(self.speeds) * len(getattr(self, direction)) * self.phases


def margin_grid(policy: Policy, grid: MarginGrid = MarginGrid(), map_fn: MapFn = map) -> dict:
    """Pushes survived on ``grid`` per direction, in all and per speed (a speed the policy
    does not walk unpushed counts every push there as lost)."""
    config = RobustnessConfig(push_duration=grid.push_duration, push_horizon=grid.horizon)
    phases = [k / grid.phases for k in range(grid.phases)]
    jobs, keys = [], []
    for speed in grid.speeds:
        times = phase_times(policy, speed, grid.settle, phases)
        for direction in DIRECTIONS:
            for impulse in grid.impulses(speed, direction):
                for time in times or ():
                    jobs.append((policy, speed, time, impulse, config))
                    keys.append((speed, direction))
    survived = {(speed, direction): 0 for speed in grid.speeds for direction in DIRECTIONS}
    for key, ok in zip(keys, map_fn(push_survived, jobs)):
        survived[key] += int(ok)
    per_speed = [{"speed": speed, **{d: survived[(speed, d)] for d in DIRECTIONS}} for speed in grid.speeds]
    return {**{d: sum(row[d] for row in per_speed) for d in DIRECTIONS},
            "of": {d: grid.pushes_per_direction(d) for d in DIRECTIONS}, "per_speed": per_speed,
            "grid": asdict(grid)}


def paper_scenarios(policy: Policy, config: EvaluationConfig = EvaluationConfig()) -> dict[str, dict]:
    """Each of the paper's push scenarios' outcome (``WalkResult.outcome()``), walked as
    ``scripts/evaluate.py`` walks it."""
    return {s.name: push_trial(policy, config.push_speed, s, config.push_duration).outcome()
            for s in config.scenarios}


def measure(policy: Policy, grid: MarginGrid = MarginGrid(), map_fn: MapFn = map) -> dict:
    """A candidate's pushes: the paper's scenarios and the margin grid."""
    return {"scenarios": paper_scenarios(policy), "margin_grid": margin_grid(policy, grid, map_fn)}


def walks_every_scenario(measured: dict) -> bool:
    return all(o["outcome"] == "walked" for o in measured["scenarios"].values())


def verdict(candidate: dict, start: dict) -> tuple[bool, list[str]]:
    """(ships, why): ``candidate`` and ``start`` each ``{"failures": acceptance checks
    failed, **measure(...)}``. Ships when it fails no more checks, walks every scenario the
    start walks and ``large_backward`` (the scenario today's learned controller falls in),
    survives more forward pushes and at least as many
    backward ones on the grid."""
    reasons = []
    if candidate["failures"] > start["failures"]:
        reasons.append(f"fails {candidate['failures']} acceptance checks, the start {start['failures']}")
    for name, outcome in candidate["scenarios"].items():
        if outcome["outcome"] != "walked" and (start["scenarios"][name]["outcome"] == "walked"
                                               or name == "large_backward"):
            reasons.append(f"{name}: {outcome['outcome']}")
    mine, theirs = candidate["margin_grid"], start["margin_grid"]
    if mine["forward"] <= theirs["forward"]:
        reasons.append(f"forward pushes {mine['forward']} of {mine['of']['forward']}, the start "
                       f"{theirs['forward']} (not more)")
    if mine["backward"] < theirs["backward"]:
        reasons.append(f"backward pushes {mine['backward']} of {mine['of']['backward']}, the start "
                       f"{theirs['backward']} (fewer)")
    return not reasons, reasons


def screen_rank(measured: dict) -> tuple:
    """Sort key, lower is better: fewest failed acceptance checks, every scenario walked,
    then most forward pushes, then most backward pushes."""
    return (measured["failures"], not walks_every_scenario(measured), -measured["margin_grid"]["forward"],
            -measured["margin_grid"]["backward"])
