# Row e probe (docs/learning.md): classic HZD with a lower Kp, no feed-forward, torque delays 0/3/5 ms
#   .venv/bin/python docs/learning/row_e/kp_probe.py
from rabbit_policy.experiment.loop import ClosedLoop
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.policies import make_policy

for kp in (3000, 2000, 1500, 1000, 600):
    row=[]
    for delay in (0.0, 0.003, 0.005):
        for v in (0.7, 1.0, 1.3):
            loop = ClosedLoop(Scenario(schedule=((0.0, v),), torque_delay=delay), make_policy("classic"), kp=kp)
            loop.run(8.0)
            sp = loop.result().mean_speed(4.0) if not loop.failed else float('nan')
            row.append(f"{delay*1000:.0f}ms@{v}:{'F' if loop.failed else f'{sp:.2f}'}")
    print(kp, " ".join(row), flush=True)
