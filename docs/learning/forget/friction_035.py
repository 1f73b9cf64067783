# Friction 0.35 (issue 37's bar: no fall), 20 s at each speed, per controller; the mean speed 10-20 s
# minus the command, or how it ended. On the package of 2026-11-28 (second).
#   .venv/bin/python docs/learning/forget/friction_035.py > docs/learning/forget/friction_035.txt
# docs/learning/start_decay/friction_035.txt: the same script on the package with the start rule
# shipped (2026-11-28 (second), later the same day).
from concurrent.futures import ProcessPoolExecutor

from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.policies import make_policy
from rabbit_sim.model import ModelOptions

SPEEDS = (0.7, 0.8, 0.9, 1.0, 1.1, 1.2, 1.3, 1.4, 1.5)


def job(args):
    kind, speed = args
    r = walk(make_policy(kind), Scenario.constant(speed, model=ModelOptions(friction=0.35)), 20.0)
    if r.failed:
        return "fell" if r.fell else "stalled"
    return f"{r.mean_speed(10.0) - speed:+.3f}"


with ProcessPoolExecutor(2) as pool:
    for kind in ("classic", "recovery", "learned"):
        out = list(pool.map(job, [(kind, s) for s in SPEEDS]))
        bad = sum(o in ("fell", "stalled") for o in out)
        print(kind, f"failed {bad} of {len(SPEEDS)}:", " ".join(f"{s}:{o}" for s, o in zip(SPEEDS, out)), flush=True)
