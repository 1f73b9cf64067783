# Row e probe: a lower Kp plus the library gait's feed-forward torques (recorded on its orbit at Kp 3000)
#   .venv/bin/python docs/learning/row_e/feedforward_probe.py
import numpy as np
from rabbit_policy.experiment.loop import ClosedLoop
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.policies import GaitCommand
from rabbit_hzd_controller.controller import Leg
LIB = GaitLibrary.load()
BINS = 50
def rel(torques, stance):
    return list(torques) if stance is Leg.LEFT else [torques[2], torques[3], torques[0], torques[1]]
def record_ff(gait):
    rows = []
    loop = ClosedLoop(Scenario(schedule=((0.0, gait.speed),)), None, GaitCommand(gait.alpha, gait.kd), start_speed=gait.speed, kp=gait.kp,
                      observer=lambda l, tq: rows.append((l.controller.tau, *rel(tq, l.controller.stance))))
    loop.run(8.0)
    a = np.array(rows[3000:])
    idx = np.minimum((a[:, 0] * BINS).astype(int), BINS - 1)
    return np.array([a[idx == b, 1:].mean(0) if np.any(idx == b) else np.zeros(4) for b in range(BINS)])
def walk(gait, ff, kp, delay):
    loop = ClosedLoop(Scenario(schedule=((0.0, gait.speed),), torque_delay=delay), None, GaitCommand(gait.alpha, gait.kd), start_speed=gait.speed, kp=kp)
    c = loop.controller; orig = c.compute
    def compute(q, dq):
        tq = orig(q, dq)
        if ff is None: return tq
        u = ff[min(int(c.tau * BINS), BINS - 1)]
        u = list(u) if c.stance is Leg.LEFT else [u[2], u[3], u[0], u[1]]
        return [max(-150.0, min(150.0, a + b)) for a, b in zip(tq, u)]
    c.compute = compute
    loop.run(10.0)
    return 'F' if loop.failed else f"{loop.result().mean_speed(5.0) - gait.speed:+.2f}"
for v in (0.7, 1.0, 1.3):
    gait = LIB.nearest(v); ff = record_ff(gait)
    for kp in (3000, 1500, 1000, 600):
        print(v, kp, "no ff:", " ".join(walk(gait, None, kp, d) for d in (0, .003, .005)), "| ff:", " ".join(walk(gait, ff, kp, d) for d in (0, .003, .005)), flush=True)
