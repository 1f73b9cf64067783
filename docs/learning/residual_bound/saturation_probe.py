# Does the residual's bound (+-0.1 rad per coefficient, +-20 N m s/rad on Kd) cap the shipped
# policy's push recovery? (docs/learning.md, "The residual's bound under pushes")
#   .venv/bin/python docs/learning/residual_bound/saturation_probe.py [--workers 2]
# 1. Saturation: the shipped policy walks at 1.0 and 1.3 m/s and is pushed at check 4's 8 phases
#    (0.1 s pushes after 3 s); per decision, the fraction of the 21 residual outputs within 10 %
#    of their bound (|2 sigmoid(y) - 1| >= 0.9), in the 1 s before the push and the 1 s from its start.
#    The walk ends 1 s after the push starts (fell_within_1_s; check 4 watches 5 s), so pushes
#    past the margin show what the policy does while it is losing, not whether it falls.
# 2. Counterfactual: the network's residual multiplied by 2 and 3 (and its bound with it; the
#    memory sees the network's own output, as trained): is the learned correction right but
#    timid? Check 4's margin procedure (whole N s, every phase) for gains 1, 2, 3, backward
#    at 0.7/1.0/1.3 and forward at 1.3 m/s.
import argparse
import json
from dataclasses import replace
from multiprocessing import Pool

import numpy as np
import torch

from rabbit_policy.evaluation.robustness import RobustnessConfig, phase_times, push_margin
from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Push, Scenario
from rabbit_policy.runtime.policies import make_policy


class Amplified(torch.nn.Module):
    """The shipped network with its residual (symmetric bounds +-scale) multiplied by ``gain``."""

    def __init__(self, net, gain: float):
        super().__init__()
        self.inner, self.gain = net, gain
        self.low, self.high = net.low, net.high  # what the memory normalises the last action by

    def forward(self, obs):
        return self.gain * self.inner(obs)


def policy(gain: float = 1.0):
    """The shipped policy, its residual multiplied by ``gain`` (its bound too); its memory sees
    the network's own output, as trained."""
    p = make_policy("learned")
    if gain != 1.0:
        p.net = Amplified(p.net, gain)
        p.residual = replace(p.residual, scale=tuple(gain * s for s in p.residual.scale))
        remember = p._remember
        p._remember = lambda a: remember(np.asarray(a) / gain)
    return p


def saturation_job(job):
    speed, t, impulse = job
    p = make_policy("learned")
    lo, hi = p.net.low.numpy().astype(float), p.net.high.numpy().astype(float)
    seen = []  # |normalised residual| per network call (the walk's first gait, then one per decision)
    inner = p.residual

    class Recording:
        def __getattr__(self, name):  # library, scale, ...: the shipped residual's
            return getattr(inner, name)

        def compose(self, residual, desired, integral=0.0):
            seen.append(np.abs(2.0 * (np.asarray(residual) - lo) / (hi - lo) - 1.0))
            return inner.compose(residual, desired, integral)
    p.residual = Recording()
    r = walk(p, Scenario.constant(speed, pushes=(Push(t, impulse / 0.1, 0.1),) if impulse else ()), t + 1.0,
             stop_on_fall=True)
    times = np.array([d.time for d in r.decisions])
    u = np.array(seen[-len(times):]) if len(times) else np.zeros((0, 21))
    before, after = u[(times >= t - 1.0) & (times < t)], u[times >= t]
    frac = lambda x: float(np.mean(x >= 0.9)) if len(x) else None
    return {"speed": speed, "push_time": t, "impulse_Ns": impulse, "fell_within_1_s": r.failed,
            "saturated_before": frac(before), "saturated_after": frac(after),
            "max_after": float(after.max()) if len(after) else None}


def margin_job(job):
    gain, speed, direction = job
    return {"gain": gain, **push_margin(policy(gain), speed, direction, RobustnessConfig())}


if __name__ == "__main__":
    parser = argparse.ArgumentParser()
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(1)
    config = RobustnessConfig()
    out = {"saturation": [], "margins": []}
    with Pool(args.workers) as pool:
        jobs = []
        for speed in (1.0, 1.3):
            times = phase_times(make_policy("learned"), speed, config.push_settle, config.push_phases)
            jobs += [(speed, t, impulse) for t in times for impulse in (0, -6, -10, -12, -17, 6)]
        out["saturation"] = pool.map(saturation_job, jobs)
        for row in out["saturation"]:
            print(json.dumps(row), flush=True)
        out["margins"] = pool.map(margin_job, [(k, v, d) for k in (1.0, 2.0, 3.0)
                                               for v, d in ((0.7, -1), (1.0, -1), (1.3, -1), (1.3, 1))])
        for row in out["margins"]:
            print(json.dumps({k: row[k] for k in ("gain", "speed", "direction", "largest_survived_Ns",
                                                  "first_failing_phases")}), flush=True)
    print(json.dumps(out))
