# Classic HZD (interpolating) on a gait library, 20 s at each speed, at the nominal friction and
# at 0.35: the mean speed 10-20 s minus the command, or how it ended.
#   .venv/bin/python docs/learning/friction/classic_on_library.py [GAIT_DIR] > OUT
# classic_on_library_030.txt: on the library refined with --friction-limit 0.3 at 1.2-1.5 m/s
# (optimize_030.log; the interpolation calibration left as the packaged library's).
# classic_on_library_030_approach.txt, _030_family.txt (library_030) and _030_bridge.txt
# (library_030_bridge): the later rounds (docs/gait_library.md); _shipped.txt: the shipped library.
import sys
from concurrent.futures import ProcessPoolExecutor

from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.policies import make_policy
from rabbit_sim.model import ModelOptions

SPEEDS = (0.7, 0.8, 0.9, 1.0, 1.1, 1.2, 1.25, 1.3, 1.35, 1.4, 1.45, 1.5)


def job(args):
    directory, friction, speed = args
    r = walk(make_policy("classic", directory), Scenario.constant(speed, model=ModelOptions(friction=friction)), 20.0)
    if r.failed:
        return "fell" if r.fell else "stalled"
    return f"{r.mean_speed(10.0) - speed:+.3f}"


if __name__ == "__main__":
    directory = sys.argv[1] if len(sys.argv) > 1 else None
    with ProcessPoolExecutor(2) as pool:
        for friction in (0.8, 0.35):
            out = list(pool.map(job, [(directory, friction, s) for s in SPEEDS]))
            bad = sum(o in ("fell", "stalled") for o in out)
            print(f"friction {friction}: failed {bad} of {len(SPEEDS)}:",
                  " ".join(f"{s}:{o}" for s, o in zip(SPEEDS, out)), flush=True)
