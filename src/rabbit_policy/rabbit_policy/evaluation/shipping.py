"""Whether a retrained learned controller ships: a paired screen on its own trials.

Every candidate and the start walk the same trials (:class:`ScreenTrials`), each trial a pass
or a fail, in three families:

* ``forward`` and ``backward``: single pushes scaled to classic HZD's own margin
  (:func:`~.push_recovery.classic_margin`) at speeds between the ones the margins were measured
  at, at evenly spaced phases of one step; a push is survived when the walk neither falls nor
  stalls within ``horizon`` s after it (:func:`~.robustness.push_survived`, the margin's rule);
* ``changes``: a command change between two speeds off the library's grid at a phase of the
  step, passed when the hip reaches the new speed within ``reach_within`` s without a fall or a
  stall (:func:`~.robustness.transition_outcome`, the evaluation's rule).

The trials are not the report's (``evaluate.py`` walks other speeds, impulses and changes), so
what is chosen here is measured afresh there.

:func:`verdict` ships a candidate only on a significant improvement over the start: more trials
passed in all, by McNemar's exact test (:func:`~.statistics.mcnemar_exact`) at ``alpha``
divided by the number of candidates screened (Bonferroni: the best of several is chosen on
these trials), no family significantly worse at ``alpha``, and no more failed acceptance
checks. :func:`screen_rank` orders candidates (most trials passed, then fewest failed checks).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

from rabbit_policy.evaluation.push_recovery import classic_margin
from rabbit_policy.evaluation.robustness import (MapFn, RobustnessConfig, phase_times, push_survived,
                                                 transition_outcome)
from rabbit_policy.evaluation.statistics import bootstrap_interval, iqm, mcnemar_exact, rate
from rabbit_policy.experiment.result import REACH_WITHIN
from rabbit_policy.runtime.gait_command import Policy

DIRECTIONS = {"forward": 1, "backward": -1}
FAMILIES = ("forward", "backward", "changes")
ALPHA = 0.05
"""The screen's significance level, before the division by the candidates screened."""


@dataclass(frozen=True)
class ScreenTrials:
    """The screen's trials. Pushes: at ``speeds`` (m/s), ``forward``/``backward`` multiples of
    classic's margin, ``phases`` evenly spaced phases of the first step after ``settle`` s (the
    k-th at ``(k + phase_offset) / phases``), each push ``push_duration`` s long, survived when
    no fall or stall follows within ``horizon`` s. Changes: every ordered pair of
    ``change_speeds`` (m/s) at each of ``change_phases`` of the step after ``change_settle`` s,
    passed when reached within ``reach_within`` s. The default is the ship screen (640 pushes,
    300 changes); :meth:`selection` the held-out trials a seed's candidate is picked on."""

    speeds: tuple[float, ...] = (0.75, 0.95, 1.05, 1.25, 1.35)
    forward: tuple[float, ...] = (1.0, 1.3)
    backward: tuple[float, ...] = (1.5, 2.0)
    phases: int = 32
    phase_offset: float = 0.0
    settle: float = 3.0
    horizon: float = 5.0
    push_duration: float = 0.1
    change_speeds: tuple[float, ...] = (0.75, 0.85, 0.95, 1.15, 1.25, 1.45)
    change_phases: tuple[float, ...] = tuple(round((k + 0.3) / 10, 2) for k in range(10))
    change_settle: float = 6.0
    change_horizon: float = 6.0
    reach_within: float = REACH_WITHIN

    def __post_init__(self) -> None:
        if (not self.speeds or self.phases < 1 or self.horizon <= 0 or self.push_duration <= 0
                or len(self.change_speeds) == 1 or self.reach_within <= 0 or not 0.0 <= self.phase_offset < 1.0):
            raise ValueError("screen trials need speeds, >= 1 phase, a phase offset in [0, 1), positive durations "
                             "and no single change speed")

    @classmethod
    def quick(cls) -> ScreenTrials:
        """One speed, one multiple per direction, two phases, two changes (tests, the tiny preset)."""
        return cls(speeds=(1.05,), forward=(1.0,), backward=(1.5,), phases=2, horizon=2.0,
                   change_speeds=(0.85, 1.15), change_phases=(0.125,), change_settle=3.0, change_horizon=4.0)

    @classmethod
    def selection(cls, quick: bool = False) -> ScreenTrials:
        """Held-out trials to pick candidates on, none of them the screen's (nor, with ``quick``,
        :meth:`quick`'s), in about the screen's proportions: pushes at other speeds and between
        the screen's phases (320, the slowest and the fastest beside the screen's own: trained networks
        lost forward pushes there first), changes between other speeds at six phases (120);
        ``quick``: 4 pushes and 2 changes."""
        if quick:
            return replace(cls.quick(), speeds=(1.15,), phase_offset=0.5, change_speeds=(0.92, 1.08),
                           change_phases=(0.375,))
        return cls(speeds=(0.78, 0.85, 1.15, 1.3, 1.4), phases=16, phase_offset=0.5,
                   change_speeds=(0.78, 0.92, 1.08, 1.22, 1.38), change_phases=tuple((k + 0.5) / 6 for k in range(6)))

    def push_phases(self) -> list[float]:
        """The pushes' phases of a step (0-1)."""
        return [(k + self.phase_offset) / self.phases for k in range(self.phases)]

    def impulses(self, speed: float, direction: str) -> list[int]:
        """The pushes' impulses (N s, signed, whole) at ``speed`` in ``direction``."""
        sign = DIRECTIONS[direction]
        return [sign * round(factor * classic_margin(speed, sign)) for factor in getattr(self, direction)]

    def count(self, family: str) -> int:
        if family == "changes":
            n = len(self.change_speeds)
            return n * (n - 1) * len(self.change_phases)
        return len(self.speeds) * len(getattr(self, family)) * self.phases


def screen_outcomes(policy: Policy, trials: ScreenTrials = ScreenTrials(), map_fn: MapFn = map) -> dict[str, list[bool]]:
    """Each family's trial outcomes (True: passed), in the trials' fixed order; a speed the
    policy does not walk unpushed counts every trial that starts there as failed."""
    config = RobustnessConfig(push_duration=trials.push_duration, push_horizon=trials.horizon,
                              transition_horizon=trials.change_horizon, reach_within=trials.reach_within)
    phases = trials.push_phases()
    jobs, slots = [], []
    outcomes: dict[str, list[bool]] = {family: [False] * trials.count(family) for family in FAMILIES}
    index = dict.fromkeys(FAMILIES, 0)
    for speed in trials.speeds:
        times = phase_times(policy, speed, trials.settle, phases)
        for direction in DIRECTIONS:
            for impulse in trials.impulses(speed, direction):
                for k in range(trials.phases):
                    if times is not None:
                        jobs.append((push_survived, (policy, speed, times[k], impulse, config)))
                        slots.append((direction, index[direction]))
                    index[direction] += 1
    for a in trials.change_speeds:
        times = phase_times(policy, a, trials.change_settle, trials.change_phases)
        for b in trials.change_speeds:
            if a == b:
                continue
            for k in range(len(trials.change_phases)):
                if times is not None:
                    jobs.append((_passed_change, (policy, a, b, times[k], config)))
                    slots.append(("changes", index["changes"]))
                index["changes"] += 1
    for (family, i), ok in zip(slots, map_fn(_run, jobs)):
        outcomes[family][i] = bool(ok)
    return outcomes


def _run(job: tuple) -> bool:
    function, arguments = job
    return function(arguments)


def _passed_change(job: tuple) -> bool:
    policy, a, b, change, config = job
    return transition_outcome(policy, a, b, change, config)["passed"]


def measure(policy: Policy, trials: ScreenTrials = ScreenTrials(), map_fn: MapFn = map) -> dict:
    """A candidate's screen: per family its outcomes and rate, and the total passed."""
    outcomes = screen_outcomes(policy, trials, map_fn)
    return {"outcomes": outcomes, "rates": {f: rate(outcomes[f]) for f in FAMILIES},
            "passed": sum(sum(o) for o in outcomes.values()), "of": sum(len(o) for o in outcomes.values()),
            "trials": asdict(trials)}


def pooled(measured: dict) -> list[bool]:
    return [ok for family in FAMILIES for ok in measured["outcomes"][family]]


def verdict(candidate: dict, start: dict, screened: int = 1, alpha: float = ALPHA) -> tuple[bool, list[str], dict]:
    """(ships, why not, tests): ``candidate`` and ``start`` each ``{"failures": acceptance
    checks failed, **measure(...)}`` on the same trials; ``screened`` candidates were compared
    with the start. Ships on a significant improvement (the module docstring); ``tests`` holds
    McNemar's test in all and per family."""
    tests = {"all": mcnemar_exact(pooled(candidate), pooled(start)), **family_tests(candidate, start)}
    level = alpha / max(1, screened)
    reasons = []
    if candidate["failures"] > start["failures"]:
        reasons.append(f"fails {candidate['failures']} acceptance checks, the start {start['failures']}")
    overall = tests["all"]
    if not (overall["only_a"] > overall["only_b"] and overall["p_value"] < level):
        reasons.append(f"not significantly better in all: {candidate['passed']} of {candidate['of']} against the "
                       f"start's {start['passed']} (p = {overall['p_value']:.3g}, needs < {level:.3g})")
    for family in worse_families(tests, alpha):
        reasons.append(f"{family} significantly worse: {sum(candidate['outcomes'][family])} against "
                       f"{sum(start['outcomes'][family])} of {len(start['outcomes'][family])} "
                       f"(p = {tests[family]['p_value']:.3g})")
    return not reasons, reasons, tests


def family_tests(candidate: dict, start: dict) -> dict:
    """McNemar's exact test of ``candidate`` against ``start`` (each :func:`measure`'s result on
    the same trials) per family: ``only_a`` the trials only the candidate passed."""
    return {f: mcnemar_exact(candidate["outcomes"][f], start["outcomes"][f]) for f in FAMILIES}


def worse_families(tests: dict, alpha: float = ALPHA) -> list[str]:
    """The families of ``tests`` (:func:`family_tests`) on which the candidate is significantly
    worse than the start: more trials only the start passed, p below ``alpha``."""
    return [f for f in FAMILIES if tests[f]["only_b"] > tests[f]["only_a"] and tests[f]["p_value"] < alpha]


def screen_rank(measured: dict) -> tuple:
    """Sort key, lower is better: most screen trials passed, then fewest failed acceptance checks."""
    return (-measured["passed"], measured["failures"])


def over_seeds(trained: list[dict], start: dict) -> dict:
    """The seeds' screen as rliable reports it: per trained candidate (one per seed) the share
    of screen trials passed and its paired gain over the start (the same trials); the IQM of
    each over the candidates with a seeded percentile bootstrap interval (95 %)."""
    shares = [r["passed"] / r["of"] for r in trained]
    gains = [(r["passed"] - start["passed"]) / r["of"] for r in trained]
    return {"candidates": len(trained), "start_share": start["passed"] / start["of"],
            "share": {"values": shares, "iqm": iqm(shares), "ci95": list(bootstrap_interval(shares))},
            "gain_over_start": {"values": gains, "iqm": iqm(gains), "ci95": list(bootstrap_interval(gains))}}
