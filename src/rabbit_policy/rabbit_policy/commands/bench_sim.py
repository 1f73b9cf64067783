"""Benchmark: closed-loop steps per second against raw ``mj_step`` steps per second on the
same model, in the same process.

    scripts/bench_sim.py [--steps 20000] [--repeats 3] [--speed 1.0] [--model paper]

All loops start from the same state on the classic gait for ``--speed``:
* raw: ``mujoco.mj_step`` in a plain Python loop with the controls held at zero;
* closed loop: :meth:`rabbit_policy.experiment.loop.ClosedLoop.run` with the classic
  policy deciding every step: the whole tick every experiment runs (controller, step,
  pushes, schedule, speed window, recording, stop rules, decisions at touchdowns);
* step only: ``HZDController.compute`` + ``Simulator.step`` and nothing else (what this
  benchmark timed before the closed loop was unified).
Each is timed ``--repeats`` times (best kept). Prints one JSON object with
``closed_loop_steps_per_s``, ``raw_steps_per_s`` and ``ratio`` (goal: >= 0.5), the step-only
figures, and the controller's own cost per tick.
"""

from __future__ import annotations

import argparse
import platform
import time

import mujoco

from rabbit_msgs_py import strict_json
from rabbit_msgs_py.cli import ArgumentParser, positive
from rabbit_msgs_py.environment import ensure_localhost_discovery


def main() -> None:
    ensure_localhost_discovery()
    from rabbit_policy.experiment.options import add_model_option

    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=20000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--speed", type=positive, default=1.0, help="the gait's speed (m/s)")
    add_model_option(parser)
    args = parser.parse_args()

    from rabbit_hzd_controller.gait_state import state_on_gait
    from rabbit_policy.experiment.loop import ClosedLoop
    from rabbit_policy.experiment.scenario import Scenario
    from rabbit_policy.runtime.gait_library import GaitLibrary
    from rabbit_policy.runtime.policies import LibraryPolicy
    from rabbit_sim.physics.model import ModelOptions

    library = GaitLibrary.load()
    gait = library.nearest(args.speed)
    scenario = Scenario.constant(gait.speed, model=ModelOptions(args.model))
    qpos, qvel = state_on_gait(gait.alpha, gait.speed)

    def raw_rate() -> float:
        loop = ClosedLoop(scenario, LibraryPolicy(library))
        model, data = loop.model, loop.data
        step = mujoco.mj_step
        start = time.perf_counter()
        for _ in range(args.steps):
            step(model, data)
        return args.steps / (time.perf_counter() - start)

    def closed_rate() -> tuple[float, bool]:
        loop = ClosedLoop(scenario, LibraryPolicy(library))
        start = time.perf_counter()
        loop.run(max_ticks=args.steps)
        elapsed = time.perf_counter() - start
        return args.steps / elapsed, loop.failed

    def step_only_rate() -> float:
        loop = ClosedLoop(scenario, LibraryPolicy(library))
        compute, step, qpos, qvel = loop.controller.compute, loop.sim.step, loop.data.qpos, loop.data.qvel
        start = time.perf_counter()
        for _ in range(args.steps):
            step(compute(qpos.tolist(), qvel.tolist()))
        return args.steps / (time.perf_counter() - start)

    def controller_rate() -> float:
        loop = ClosedLoop(scenario, LibraryPolicy(library))
        compute = loop.controller.compute
        q, dq = list(qpos), list(qvel)
        start = time.perf_counter()
        for _ in range(args.steps):
            compute(q, dq)
        return args.steps / (time.perf_counter() - start)

    raw = max(raw_rate() for _ in range(args.repeats))
    closed_runs = [closed_rate() for _ in range(args.repeats)]
    closed = max(r for r, _ in closed_runs)
    step_only = max(step_only_rate() for _ in range(args.repeats))
    ctrl = max(controller_rate() for _ in range(args.repeats))
    print(strict_json.dumps({
        "closed_loop_steps_per_s": round(closed, 1),
        "raw_steps_per_s": round(raw, 1),
        "ratio": round(closed / raw, 3),
        "step_only_steps_per_s": round(step_only, 1),
        "step_only_ratio": round(step_only / raw, 3),
        "controller_ticks_per_s": round(ctrl, 1),
        "controller_us_per_tick": round(1e6 / ctrl, 2),
        "closed_loop_fell": any(f for _, f in closed_runs),
        "steps": args.steps,
        "repeats": args.repeats,
        "model": args.model,
        "gait_speed": gait.speed,
        "mujoco": mujoco.__version__,
        "python": platform.python_version(),
    }))


if __name__ == "__main__":
    main()
