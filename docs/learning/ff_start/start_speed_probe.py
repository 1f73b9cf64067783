# Every walk starts on its gait at phase 0 with the hip moving at the command (gait_state.state_on_gait),
# and the first step runs 15-25 % slow for every controller (classic at 0.8 m/s: 0.586). Probe: the
# same walk started with the hip faster (ClosedLoop's start_speed = factor x command): the first
# steps and the mean speed 3-6 s after the start (the start segment of make demo), per controller.
#   .venv/bin/python docs/learning/ff_start/start_speed_probe.py > docs/learning/ff_start/start_speed_probe.txt
from rabbit_policy.experiment.loop import ClosedLoop
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.policies import make_policy

for kind in ("classic", "learned"):
    for speed in (0.8, 1.0, 1.3):
        for factor in (1.0, 1.15, 1.3, 1.45):
            loop = ClosedLoop(Scenario.constant(speed), make_policy(kind), start_speed=factor * speed)
            loop.run(max_ticks=10000)
            r = loop.result()
            steps = " ".join(f"{v:.3f}" for _, _, v in r.step_speeds()[:5])
            print(f"{kind} {speed} start x{factor}: first steps {steps}; mean 3-6 s {r.mean_speed(3.0, 6.0):.3f}"
                  f" ({r.mean_speed(3.0, 6.0) - speed:+.3f}); 6-10 s {r.mean_speed(6.0, 10.0) - speed:+.3f}"
                  + (" FAILED" if r.failed else ""), flush=True)
