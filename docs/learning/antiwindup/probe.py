# Issue 37 item 4: does holding the speed integral after a command change remove the shipped policy's
# overshoot (docs/learning.md, 2026-11-27 (fourth): the integral winds to an offset of +-0.12 m/s while the
# hip lags the new command, and takes about 10 s to unwind)?  A probe on the shipped network, not retrained:
# the integral (its memory input and its offset on the base gait, the same number) is held for HOLD s after
# each change of the command (patched in here), or integrates only while |v_d - v̄| < BAND m/s (MemoryConfig.band),
# or integrates the error clipped to +-CLIP m/s (MemoryConfig.clip), or (chg:B:T) after a command change is held
# while |v_d - v̄| >= B m/s, until the error first falls below B or T s have passed (patched in here).
#   .venv/bin/python docs/learning/antiwindup/probe.py none hold:2 band:0.05 ... >> docs/learning/antiwindup/probe.jsonl
#   .venv/bin/python docs/learning/antiwindup/probe.py none band:0.1 --changes 200 --seed 38 >> docs/learning/antiwindup/probe.jsonl
# Each variant: the changes of docs/learning/settling/settling.py (default its 60, seed 37), settled as there.
import argparse
import json
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "settling"))
from settling import TOLERANCE, draws  # noqa: E402

from rabbit_policy.experiment.loop import walk  # noqa: E402
from rabbit_policy.experiment.scenario import Scenario  # noqa: E402
from rabbit_policy.runtime.network import PolicyCheckpoint  # noqa: E402
from rabbit_policy.runtime.policies import LearnedPolicy, make_policy, packaged_policy_file  # noqa: E402


def patched(variant: str):
    kind, _, value = variant.partition(":")
    value, _, cap = value.partition(":")
    value, cap = float(value or 0.0), float(cap or 0.0)
    if kind in ("band", "clip"):  # the implementation itself (MemoryConfig), on a copy of the shipped checkpoint
        with tempfile.TemporaryDirectory() as scratch:
            checkpoint = PolicyCheckpoint.load(packaged_policy_file())
            checkpoint.info["memory"][kind] = value
            checkpoint.save(Path(scratch) / "band.pt")
            return LearnedPolicy(Path(scratch) / "band.pt")
    policy = make_policy("learned")
    integral = policy.memory._integral
    update = integral.update
    state = {"last": None, "held": 0}

    def held_update(error: float, desired_speed: float) -> float:
        if state["last"] is not None and desired_speed != state["last"]:
            state["held"] = int(round((cap if kind == "chg" else value) / integral.config.dt))
        state["last"] = desired_speed
        if kind == "chg" and state["held"] > 0:  # after a change: held while |error| >= band, at most cap s
            state["held"] -= 1
            if abs(error) >= value:
                return integral.value
            state["held"] = 0  # caught up: integrates as before from here on
        if kind == "hold" and state["held"] > 0:
            state["held"] -= 1
            return integral.value
        return update(error, desired_speed)

    reset = integral.reset

    def held_reset() -> None:
        state.update(last=None, held=0)
        reset()

    if kind != "none":
        integral.update, integral.reset = held_update, held_reset
    return policy


def measure(variant: str, changes: int = 60, seed: int = 37) -> dict:
    policy = patched(variant)
    rows = []
    for a, b, t in draws(changes, seed):
        result = walk(policy, Scenario(schedule=((0.0, a), (t, b))), t + 10.0)
        late = None if result.failed else result.mean_speed(t + 5.0, t + 10.0) - b
        rows.append((a, b, t, result.failed, late))
    errors = [r[4] for r in rows if r[4] is not None]
    return {"variant": variant, "changes": changes, "seed": seed,
            "settled": sum(e is not None and abs(e) <= TOLERANCE for e in (r[4] for r in rows)),
            "failed": sum(r[3] for r in rows), "worst_abs_error": max(map(abs, errors)),
            "mean_signed_error": sum(errors) / len(errors), "rows": rows}


if __name__ == "__main__":
    parser = argparse.ArgumentParser()
    parser.add_argument("variants", nargs="+", help="none, hold:S (s), band:B (m/s), clip:C (m/s), chg:B:T (m/s, s)")
    parser.add_argument("--changes", type=int, default=60)
    parser.add_argument("--seed", type=int, default=37)
    args = parser.parse_args()
    for variant in args.variants:
        print(json.dumps(measure(variant, args.changes, args.seed)), flush=True)
