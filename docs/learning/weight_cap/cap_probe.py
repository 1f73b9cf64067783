# Does the rule want more than its offsets at large deficits? Probe: the weight w = deficit / full
# capped at WMAX instead of 1 (offsets x w up to WMAX), on the package of ec29e5a (forgets at 0.9).
# Repeated pushes as repeated_pushes/repeated.py, and check 4's backward margins.
#   .venv/bin/python docs/learning/weight_cap/cap_probe.py WMAX > docs/learning/weight_cap/cap_WMAX.txt
import sys
from concurrent.futures import ProcessPoolExecutor

from rabbit_policy.runtime import recovery as R

WMAX = float(sys.argv[1]) if len(sys.argv) > 1 else 1.0


def weight(self, tau, fraction, reference):
    if reference is None or not 0.0 < tau < 1.0:
        return 0.0
    deficit = reference - fraction - self.config.threshold
    return min(max(deficit / self.config.full, 0.0), WMAX)


R.RecoveryPolicy.weight = weight


def trial(job):
    from rabbit_policy.evaluation.push_recovery import PushScenario, push_trial
    from rabbit_policy.runtime.policies import make_policy
    kind, speed, impulse, t0 = job
    scenario = PushScenario("r", impulse / 0.1, times=(t0, t0 + 2.0, t0 + 4.0))
    return not push_trial(make_policy(kind), speed, scenario).failed


IMPULSES = {0.7: (-8, -10, -12, -14), 1.0: (-13, -16, -19, -22), 1.3: (-18, -22, -26, -30)}
OFFSETS = (2.0, 2.1, 2.2, 2.3, 2.4, 2.5)


def main():
    from rabbit_policy.evaluation.robustness import RobustnessConfig, push_margin
    from rabbit_policy.runtime.policies import make_policy
    with ProcessPoolExecutor(2) as pool:
        for kind in ("recovery", "learned"):
            ok = list(pool.map(trial, [(kind, s, i, t) for s, imps in IMPULSES.items() for i in imps for t in OFFSETS]))
            print(f"wmax {WMAX} {kind} repeated pushes survived {sum(ok)}/72", flush=True)
            row = [push_margin(make_policy(kind), s, -1, RobustnessConfig(), pool.map)["largest_survived_Ns"]
                   for s in (0.7, 1.0, 1.3)]
            print(f"wmax {WMAX} {kind} backward margins 0.7 · 1.0 · 1.3: {row}", flush=True)


if __name__ == "__main__":
    main()
