# Row e probe (docs/learning.md): classic HZD with the controller fed the state predicted h s ahead (q + h dq)
#   .venv/bin/python docs/learning/row_e/prediction_probe.py
from rabbit_policy.experiment.loop import ClosedLoop
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.policies import make_policy

def run(v, delay, horizon):
    loop = ClosedLoop(Scenario(schedule=((0.0, v),), torque_delay=delay), make_policy("classic"))
    c = loop.controller; orig = c.compute
    def pred(q, dq):
        return orig([a + b * horizon for a, b in zip(q, dq)], dq)
    if horizon: c.compute = pred
    loop.run(8.0)
    return 'F' if loop.failed else f"{loop.result().mean_speed(4.0):.2f}"
for delay in (0.0, 0.003, 0.004, 0.005):
    print(f"delay {delay*1000:.0f} ms:", " | ".join(f"h={h*1000:.0f}ms " + " ".join(run(v, delay, h) for v in (0.7, 1.0, 1.3)) for h in (0.0, delay/2, delay) if h or True), flush=True)
