# The walk's start as a change of the command (0 -> v_d) for the integral's windup decay
# (docs/learning.md 2026-11-28 (second)). Every walk's first steps run slow, I winds up, and the
# walk then runs fast for seconds (make demo's start segment, settling after a change at 6-7 s
# made while I still unwinds, check 4's forward margin at 1.3 m/s at 3 s). Probe: at a walk's
# first decision the decay watches for the hip passing v_d as after a change up, and decays what
# I wound up toward its value at the start (VARIANT "decay"), also with the feed-forward's start
# (I starts at I*(v_d), VARIANT "decay+ff").
#   .venv/bin/python docs/learning/start_decay/probe.py VARIANT > docs/learning/start_decay/probe_VARIANT.txt
import sys
from concurrent.futures import ProcessPoolExecutor

from rabbit_policy.runtime import speed_integral as si

VARIANT = sys.argv[1] if len(sys.argv) > 1 else "none"
_update = si.SpeedIntegral.update


def update(self, error, desired_speed):
    first = self._last_command is None
    value = _update(self, error, desired_speed)
    if first and self.config.windup_decay is not None and VARIANT != "none":
        self._anchor = self.value - error * self.config.dt  # I at the start, before this decision's error
        self._looking, self._direction, self._decaying, self._since = self._window, desired_speed, False, 1
    return value


si.SpeedIntegral.update = update


SHIPPED = "src/rabbit_policy/rabbit_policy/trained/hzd_rl_policy.pt"
VARIANT_FILE = "/tmp/start_decay_ff.pt"  # the shipped checkpoint with the feed-forward's start on


def write_variant() -> None:
    import torch
    c = torch.load(SHIPPED, weights_only=False)
    c["info"]["memory"]["feedforward"]["start"] = True
    torch.save(c, VARIANT_FILE)


def policy():
    from rabbit_policy.runtime.policies import LearnedPolicy
    return LearnedPolicy(VARIANT_FILE if VARIANT == "decay+ff" else SHIPPED)


def start_error(speed):
    from rabbit_policy.experiment.loop import walk
    from rabbit_policy.experiment.scenario import Scenario
    r = walk(policy(), Scenario.constant(speed), 10.0)
    return None if r.failed else (round(r.mean_speed(3.0, 6.0) - speed, 3), round(r.mean_speed(6.0, 10.0) - speed, 3))


def demo(_):
    from rabbit_policy.experiment.loop import walk
    from rabbit_policy.experiment.scenario import Push, Scenario
    schedule = ((0.0, 0.8), (6.0, 1.4), (13.0, 0.9), (18.0, 1.2))
    r = walk(policy(), Scenario(schedule=schedule, pushes=(Push(20.0, -60.0, 0.1),)), 26.0)
    return [round(s["mean_speed"], 3) for s in r.segments()]


def settle(row):
    from rabbit_policy.experiment.loop import walk
    from rabbit_policy.experiment.scenario import Scenario
    a, b, t = row
    r = walk(policy(), Scenario(schedule=((0.0, a), (t, b))), t + 10.0)
    return None if r.failed else r.mean_speed(t + 5.0, t + 10.0) - b


def main():
    sys.path.insert(0, "docs/learning/settling")
    import settling
    speeds = [round(0.7 + 0.05 * i, 2) for i in range(17)]
    if VARIANT == "decay+ff":
        write_variant()
    with ProcessPoolExecutor(2) as pool:
        errors = list(pool.map(start_error, speeds))
        within = sum(e is not None and abs(e[0]) <= 0.03 for e in errors)
        print(VARIANT, "start: mean speed 3-6 s and 6-10 s minus command:", " ".join(f"{s}:{e}" for s, e in zip(speeds, errors)),
              f"3-6 s within 0.03: {within}/17", flush=True)
        print(VARIANT, "make demo's schedule (ROS-free):", list(pool.map(demo, [0]))[0], flush=True)
        rows = settling.draws(100, 40)
        late = list(pool.map(settle, rows))
        ok = sum(e is not None and abs(e) <= 0.03 for e in late)
        print(VARIANT, f"settling, the first 100 changes of seed 40: {ok}/100", flush=True)


if __name__ == "__main__":
    main()
