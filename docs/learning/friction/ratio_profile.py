# How much friction each library gait needs (issue 37's bar: no fall at friction 0.35).
# Each gait walked alone (walk_gait) 10 s at the nominal friction 0.8; over the last 5 s, the
# stance foot's |F_t|/F_n sampled every tick: its max, its 99th percentile, the share of stance
# ticks above 0.35, and where in the step (tau) those ticks are. Then the same gait at 0.35.
#   .venv/bin/python docs/learning/friction/ratio_profile.py [GAIT_DIR] > docs/learning/friction/ratio_profile.txt
# GAIT_DIR: a library directory (default: the packaged one); ratio_profile_030.txt is the library
# refined with --friction-limit 0.3 (optimize_030.log).
# ratio_profile_030_approach.txt: on library_030's first round with the approach term.
import sys
import math
from concurrent.futures import ProcessPoolExecutor

import mujoco
import numpy as np

from rabbit_policy.experiment.loop import ClosedLoop, walk_gait
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.policies import GaitCommand
from rabbit_sim.model import ModelOptions


def profile(args: tuple[float, str | None]) -> str:
    speed, directory = args
    gait = GaitLibrary.load(directory).nearest(speed)
    loop = ClosedLoop(Scenario.constant(gait.speed), start=GaitCommand(gait.alpha, gait.kd), kp=gait.kp)
    model, data = loop.model, loop.data
    feet = (model.geom("left_foot").id, model.geom("right_foot").id)
    force = np.zeros(6)
    rows = []

    def observe(lp, torques):
        if lp.ticks < 5000:
            return
        stance = feet[int(lp.controller.stance)]
        for c in range(data.ncon):
            con = data.contact[c]
            if stance in (con.geom1, con.geom2):
                mujoco.mj_contactForce(model, data, c, force)
                if force[0] > 1.0:
                    rows.append((math.hypot(force[1], force[2]) / force[0], lp.controller.tau))

    loop.observer = observe
    loop.run(max_ticks=10000)
    r = np.array([a for a, _ in rows])
    tau = np.array([t for _, t in rows])
    over = r > 0.35
    where = np.histogram(tau[over], bins=5, range=(0, 1))[0] / max(1, len(r))
    low = walk_gait(gait, 20.0, ModelOptions(friction=0.35))
    end = "fell" if low.fell else ("stalled" if low.stalled else f"walks {low.mean_speed(10.0):.3f}")
    return (f"{gait.speed:.2f}: max {r.max():.2f} p99 {np.quantile(r, 0.99):.2f} p90 {np.quantile(r, 0.9):.2f} "
            f"share>0.35 {over.mean():.3f} by tau fifths {' '.join(f'{w:.3f}' for w in where)} | at mu 0.35: {end}")


if __name__ == "__main__":
    directory = sys.argv[1] if len(sys.argv) > 1 else None
    lib = GaitLibrary.load(directory)
    with ProcessPoolExecutor(2) as pool:
        for line in pool.map(profile, [(g.speed, directory) for g in lib.gaits]):
            print(line, flush=True)
