"""Probe (learning.md, 2026-11-28 (fifth)): pushes survived by variants of the learned spec.

    python docs/learning/forward_probe.py NAME,NAME,... [--big] [--fwd] [--detail]

NAME: classic, recovery, shipped, nooverlay, zeronet (the network's last layer zero),
zeronet_nooverlay, integral:FIELD=V (speed_integral), ov:FIELD=V (overlay), rule:FIELD=V
(recovery_rule), wscale:F (the last layer times F), spec:FILE. Default grid: forward 24 and 32 N s,
backward 14 and 20 N s at 0.85 and 1.15 m/s, 8 phases; --big: 1.1x and 1.4x classic's forward
margin, 1.5x and 2x its backward margin at 0.75, 0.95, 1.05, 1.25 and 1.35 m/s, 16 phases.
Survived: no fall or stall within 5 s after the push (robustness.push_survived)."""

import dataclasses
import json
import sys
import time
from multiprocessing import Pool

import numpy as np

from rabbit_policy.evaluation.push_recovery import classic_margin
from rabbit_policy.evaluation.robustness import RobustnessConfig, phase_times, push_survived
from rabbit_policy.spec.build import build, load_controller
from rabbit_policy.spec.files import load_weights, packaged_spec
from rabbit_policy.spec.schema import load_spec

SPEC = packaged_spec("learned")
CONFIG = RobustnessConfig(push_horizon=5.0)
PARTS = {"integral": "speed_integral", "ov": "overlay", "rule": "recovery_rule"}


def variant(name: str):
    spec = load_spec(SPEC)
    if name in ("classic", "recovery", "shipped"):
        return load_controller(packaged_spec("learned" if name == "shipped" else name))
    if name.startswith("spec:"):
        return load_controller(name[5:])
    if name.split(":")[0] in PARTS:
        part, _, assignment = name.partition(":")
        key, value = assignment.split("=")
        field = PARTS[part]
        value = None if value == "none" else float(value)
        return build(dataclasses.replace(spec, **{field: dataclasses.replace(getattr(spec, field), **{key: value})}),
                     SPEC.parent)
    if name == "nooverlay":
        return build(dataclasses.replace(spec, overlay=None, recovery_rule=None), SPEC.parent)
    weights, biases = (list(a) for a in load_weights(spec.network.weights.file, spec.network.weights.sha256,
                                                     SPEC.parent, len(spec.network.hidden) + 1))
    factor = 0.0 if name.startswith("zeronet") else float(name.split(":")[1])
    weights[-1], biases[-1] = np.asarray(weights[-1]) * factor, np.asarray(biases[-1]) * factor
    if name == "zeronet_nooverlay":
        spec = dataclasses.replace(spec, overlay=None, recovery_rule=None)
    return build(spec, SPEC.parent, weights=(weights, biases))


def job(case: tuple) -> tuple:
    name, speed, time_s, impulse = case
    return case, push_survived((variant(name), speed, time_s, impulse, CONFIG))


def main() -> None:
    names, big = sys.argv[1].split(","), "--big" in sys.argv
    speeds = (0.75, 0.95, 1.05, 1.25, 1.35) if big else (0.85, 1.15)
    phases = [i / (16 if big else 8) for i in range(16 if big else 8)]
    cases = []
    for name in names:
        policy = variant(name)
        for speed in speeds:
            times = phase_times(policy, speed, 3.0, phases)
            impulses = ((round(1.1 * classic_margin(speed, 1)), round(1.4 * classic_margin(speed, 1)),
                         -round(1.5 * classic_margin(speed, -1)), -round(2.0 * classic_margin(speed, -1)))
                        if big else (24, 32, -14, -20))
            cases += [(name, speed, t, i) for i in (impulses[:2] if "--fwd" in sys.argv else impulses) for t in times]
    start = time.time()
    with Pool(2) as pool:
        results = pool.map(job, cases)
    totals: dict[str, int] = {}
    for (name, _, _, impulse), ok in results:
        key = f"{name} {'forward' if impulse > 0 else 'backward'}"
        totals[key] = totals.get(key, 0) + int(ok)
    print(json.dumps(totals, indent=1), f"{time.time() - start:.0f} s")
    if "--detail" in sys.argv:
        for name in names:
            for speed in speeds:
                for impulse in sorted({c[3] for c, _ in results if c[0] == name and c[1] == speed and c[3] > 0}):
                    row = "".join(str(int(ok)) for c, ok in results if c[:2] == (name, speed) and c[3] == impulse)
                    print(f"{name[:30]:30s} {speed} {impulse:+d}: {row}")


if __name__ == "__main__":
    main()
