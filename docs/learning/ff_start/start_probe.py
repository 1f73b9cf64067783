# The integral's feed-forward at a walk's start (IntegralFeedforward.start), on the shipped file of
# 2026-11-28 (second): first the walk's start, then the demo's schedule (ROS-free), check 6.
#   .venv/bin/python docs/learning/ff_start/start_probe.py SHIPPED.pt VARIANT.pt > docs/learning/ff_start/start_probe.txt
# VARIANT.pt: the shipped checkpoint with info["memory"]["feedforward"]["start"] = True.
import sys
from concurrent.futures import ProcessPoolExecutor

from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Push, Scenario
from rabbit_policy.runtime.policies import LearnedPolicy

FILES = {"shipped": sys.argv[1], "start": sys.argv[2]}
SPEEDS = [round(0.7 + 0.05 * i, 2) for i in range(17)]


def start_error(job):
    name, speed = job
    r = walk(LearnedPolicy(FILES[name]), Scenario.constant(speed), 10.0)
    if r.failed:
        return None
    return float(r.mean_speed(3.0, 6.0) - speed)


def demo(name):
    schedule = ((0.0, 0.8), (6.0, 1.4), (13.0, 0.9), (18.0, 1.2))
    r = walk(LearnedPolicy(FILES[name]), Scenario(schedule=schedule, pushes=(Push(20.0, -60.0, 0.1),)), 26.0)
    return r.failed, [round(seg["mean_speed"], 3) for seg in r.segments()]


def main():
    with ProcessPoolExecutor(2) as pool:
        for name in FILES:
            errors = list(pool.map(start_error, [(name, s) for s in SPEEDS]))
            within = sum(e is not None and abs(e) <= 0.03 for e in errors)
            print(name, "start: mean speed 3-6 s minus command, per speed:",
                  " ".join(f"{s}:{'fell' if e is None else f'{e:+.3f}'}" for s, e in zip(SPEEDS, errors)),
                  f"within 0.03: {within}/{len(SPEEDS)}", flush=True)
        for name, (failed, means) in zip(FILES, pool.map(demo, list(FILES))):
            print(name, "make demo's schedule (ROS-free), segment means (second halves):", means,
                  "fell/stalled" if failed else "walked", flush=True)


if __name__ == "__main__":
    main()
