"""Benchmark HZD-RL training: environment throughput and wall time to a passing policy.

    scripts/bench_train.py [--steps 600] [--workers 2] [--train] [--algo es|ppo] [--max-iterations 60]
                           [--backend local|ray] [--ray-address ADDRESS|auto] [--no-backends]

Prints one JSON object:
* ``env_steps_per_s_per_core``: ``RabbitHZD-v0`` steps per second in one process with the
  decision rate of every policy shipped (one step = 20 ticks = 20 ms of simulation; the paper's episodes),
  the warm-started policy acting (its numpy forward pass included, as training decides), resets included;
  ``per_walking_step`` the same with one env step per walking step (0.4-0.7 s).
* ``sim_seconds_per_s_per_core``: the same in simulated seconds per wall second.
* ``pool_env_steps_per_s``: the same with ``--workers`` processes in parallel (all cores).
* ``backends`` (unless ``--no-backends``): ES generations (the first shipped configuration, shorter
  episodes: :data:`BENCH_ES`) on ``local`` and ``ray`` with 1 and 2 workers — env steps
  per second (the first generation, which builds each worker's environment, untimed),
  ``identical`` (the same parameters on every backend), Ray's start-up time (a private
  instance, or joining ``--ray-address``), ``ray_overhead_2_workers`` (1 - ray/local rate),
  ``efficiency_2_workers`` (rate ratio over the ideal for the generation's 2 pairs + 1 tasks)
  and ``projection``: the wall time of the shipped policy's ES generations (its checkpoint's
  generations and env steps) on N cores, from those figures (ceil(tasks/N) waves each).
* with ``--train``: runs ``scripts/train.py`` with the first shipped configuration (:data:`CONFIGS`)
  for ``--max-iterations`` into a temporary directory, then the acceptance checks 1-6
  (``broad_acceptance``, the full evaluation) on its ``best.pt``; reports the training wall
  time, env steps, ``passes_1_6`` and the failed checks, and ``time_to_pass_1_6_s`` (the
  wall time from nothing — warm start, training, evaluations — to that policy if it passes
  1-6; null otherwise). The tracking-check figures of the run (``first_tracking_pass``)
  come with it.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from rabbit_msgs_py import strict_json
from rabbit_msgs_py.cli import ArgumentParser
from rabbit_policy.parallel import LocalBackend, add_backend_arguments, backend_config


# The configurations of the first shipped ES policy (config/train/first_shipped_es.yaml) and of the PPO result
# reported beside it: warm start with speed feedback, decisions every 20 ticks, the broad
# episode distribution.
COMMON = ["--warm-start", "feedback", "--decision-period", "20", "--distribution", "broad", "--max-steps", "500",
          "--eval-every", "5"]
CONFIGS = {
    "es": COMMON + ["--pairs", "8", "--sigma", "0.005", "--lr", "0.002", "--episodes", "6"],
    "ppo": COMMON + ["--envs", "4", "--steps", "256", "--ppo-lr", "0.0001", "--target-kl", "0.02",
                     "--init-log-std", "-3.5"],
}


def env_throughput(steps: int, seed: int = 0, decision_period: int = 20) -> tuple[float, float]:
    """(env steps per s, simulated s per s) in this process."""
    import torch

    from rabbit_policy.learning.env import RabbitHZDEnv
    from rabbit_policy.runtime.network import HZDPolicyNet, NetworkForward
    from rabbit_policy.learning.warm_start import WARM_STARTS, warm_start

    torch.set_num_threads(1)
    torch.manual_seed(seed)
    env = RabbitHZDEnv(max_steps=500 if decision_period else 30, decision_period=decision_period)
    net = HZDPolicyNet(env.bounds.low, env.bounds.high)
    warm_start(net, env.library, seed=seed, config=WARM_STARTS["interpolate"])
    forward = NetworkForward.of(net)  # what training and the loops decide with (numpy, not torch)
    obs, _ = env.reset(seed=seed)
    sim_time, episode_start = 0.0, 0.0
    start = time.perf_counter()
    for _ in range(steps):
        action = forward(obs)
        obs, _r, terminated, truncated, info = env.step(env.bounds.to_normalised(action))
        if terminated or truncated:
            sim_time += info["time"]
            obs, _ = env.reset()
            episode_start = 0.0
        else:
            episode_start = info["time"]
    wall = time.perf_counter() - start
    return steps / wall, (sim_time + episode_start) / wall


# Throughput workload: the first shipped ES configuration (first_shipped_es.yaml: the paper's network) with fewer
# pairs and shorter episodes, so that each backend's measurement takes seconds.
BENCH_ES = {"pairs": 4, "episodes": 2, "max_steps": 500, "decision_period": 20, "distribution": "broad",
            "fall_penalty": -50.0, "seed": 0}
PROJECTION_CORES = (1, 2, 4, 8, 17, 34, 64)


def es_rate(config, generations: int = 2) -> dict:
    """ES env steps per second on the backend ``config`` (a :class:`BackendConfig`), the
    backend's start-up time and the final parameters (to compare backends)."""
    import numpy as np
    import torch

    from rabbit_policy.learning.env import RabbitHZDEnv
    from rabbit_policy.learning.es import ESConfig, EvolutionStrategy
    from rabbit_policy.parallel import make_backend
    from rabbit_policy.runtime.network import HZDPolicyNet

    start = time.perf_counter()
    backend = make_backend(config)
    startup = time.perf_counter() - start
    try:
        env = RabbitHZDEnv()
        torch.manual_seed(0)
        es = EvolutionStrategy(HZDPolicyNet(env.bounds.low, env.bounds.high),
                               ESConfig(workers=config.workers, **BENCH_ES), backend)
        es.step()  # every worker builds its environment: not timed
        before, start = es.env_steps, time.perf_counter()
        for _ in range(generations):
            es.step()
        wall = time.perf_counter() - start
        return {"backend": config.kind, "workers": config.workers, "startup_s": round(startup, 2),
                "env_steps_per_s": round((es.env_steps - before) / wall, 1), "theta": np.asarray(es.theta)}
    finally:
        backend.close()


def projection(per_core_rate: float, efficiency: float, startup_s: float) -> dict:
    """Projected wall time (s) of one seed of the shipped preset's ES generations on N cores
    (``config/reproduce/shipped.yaml``; the generations and env steps of seed 0's run as the
    packaged learned spec records it, the acceptance evaluations between them not included):
    each generation ceil(tasks / N) waves of one task's env steps at ``per_core_rate`` x
    ``efficiency`` (the measured 2-worker efficiency, the waves taken out), plus the
    backend's start-up."""
    from rabbit_policy.commands.reproduce import load_preset
    from rabbit_policy.spec import load_spec, packaged_spec

    train = load_preset("shipped")["train"]
    run = load_spec(packaged_spec("learned")).provenance["runs"][0]
    tasks = 2 * train["pairs"] + 1
    steps_per_task = run["env_steps"] / (run["iterations"] * tasks)
    task_s = steps_per_task / (per_core_rate * efficiency)
    return {"generations": run["iterations"], "env_steps": run["env_steps"], "tasks_per_generation": tasks,
            "measured_wall_s": run["wall_s"], "measured_workers": train["workers"],
            "wall_s_on_cores": {str(n): round(startup_s + run["iterations"] * math.ceil(tasks / n) * task_s, 1)
                                for n in PROJECTION_CORES}}


def backend_report(ray_address: str | None, repeats: int = 3) -> dict:
    """Local vs Ray ES throughput with 1 and 2 workers (2 workers ``repeats`` times,
    alternating, the medians compared: runs on a 2-core machine vary by 10 %), and the
    projection."""
    import numpy as np

    from rabbit_policy.parallel import BackendConfig

    def run(kind: str, workers: int) -> dict:
        return es_rate(BackendConfig(kind, workers, ray_address if kind == "ray" else None))

    runs = [run(kind, 1) for kind in ("local", "ray")]
    runs += [run(kind, 2) for _ in range(repeats) for kind in ("local", "ray")]
    identical = all(np.array_equal(r["theta"], runs[0]["theta"]) for r in runs)
    rate = {(kind, workers): float(np.median([r["env_steps_per_s"] for r in runs
                                              if r["backend"] == kind and r["workers"] == workers]))
            for kind in ("local", "ray") for workers in (1, 2)}
    ray_start = float(np.median([r["startup_s"] for r in runs if r["backend"] == "ray"]))
    tasks = 2 * BENCH_ES["pairs"] + 1
    ideal = tasks / math.ceil(tasks / 2)  # the speed-up 2 workers can give on this many tasks
    efficiency = {kind: rate[(kind, 2)] / rate[(kind, 1)] / ideal for kind in ("local", "ray")}
    return {
        "workload": BENCH_ES, "identical": identical,
        "runs": [{k: v for k, v in r.items() if k != "theta"} for r in runs],
        "median_env_steps_per_s": {f"{kind}_{workers}": rate[(kind, workers)] for kind, workers in rate},
        "ray_startup_s": round(ray_start, 2),
        "ray_overhead_2_workers": round(1 - rate[("ray", 2)] / rate[("local", 2)], 3),
        "efficiency_2_workers": {kind: round(e, 3) for kind, e in efficiency.items()},
        "projection": {kind: projection(rate[(kind, 1)], efficiency[kind], ray_start if kind == "ray" else 0.0)
                       for kind in ("local", "ray")},
    }


def _worker(args: tuple[int, int]) -> tuple[float, float]:
    return env_throughput(*args)


def acceptance_1_6(policy_file: Path, workers: int) -> dict:
    """The learning issue's checks 1-6 on a policy file (the full broad evaluation)."""
    from rabbit_policy.evaluation.acceptance import broad_acceptance
    from rabbit_policy.spec.make import make_policy

    backend = LocalBackend(workers)
    try:
        return broad_acceptance(make_policy("learned", policy_file=policy_file), make_policy("classic"),
                                map_fn=backend.map)
    finally:
        backend.close()


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=600, help="env steps per throughput measurement")
    parser.add_argument("--train", action="store_true", help="also measure the wall time to a passing policy")
    parser.add_argument("--algo", choices=("es", "ppo"), default="es")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--max-iterations", type=int, default=60)
    parser.add_argument("--no-backends", action="store_true", help="skip the local vs Ray comparison")
    parser.add_argument("--repeats", type=int, default=3, help="2-worker runs per backend (medians compared)")
    add_backend_arguments(parser)
    args = parser.parse_args(argv)
    try:
        backend_config(args)
    except ValueError as exc:
        parser.error(str(exc))
    if args.repeats < 1:
        parser.error("--repeats must be >= 1")

    single, sim_rate = env_throughput(args.steps)
    per_step, per_step_sim = env_throughput(max(args.steps // 20, 30), decision_period=0)
    start = time.perf_counter()
    pool = LocalBackend(args.workers)
    try:
        rates = pool.map(_worker, [(args.steps, i) for i in range(args.workers)])
    finally:
        pool.close()
    pool_wall = time.perf_counter() - start  # includes the warm starts: use the per-process rates
    report = {
        "env_steps_per_s_per_core": round(single, 1),
        "sim_seconds_per_s_per_core": round(sim_rate, 1),
        "per_walking_step": {"env_steps_per_s_per_core": round(per_step, 1),
                             "sim_seconds_per_s_per_core": round(per_step_sim, 1)},
        "pool_workers": args.workers,
        "pool_env_steps_per_s": round(sum(r for r, _ in rates), 1),
        "pool_wall_s": round(pool_wall, 1),
    }
    if not args.no_backends:
        from rabbit_policy.parallel import BackendUnavailable

        try:
            report["backends"] = backend_report(args.ray_address, args.repeats)
        except BackendUnavailable as exc:
            parser.exit(2, f"error: {exc}\n")
    if args.train:
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "run"
            config = CONFIGS[args.algo]
            command = [sys.executable, "-m", "rabbit_policy.commands.train", "--algo", args.algo, "--seed",
                       str(args.seed), "--workers", str(args.workers), "--out", str(out), "--iterations",
                       str(args.max_iterations), "--no-progress", "--backend", args.backend, *config]
            if args.ray_address:
                command += ["--ray-address", args.ray_address]
            start = time.perf_counter()
            result = subprocess.run(command, capture_output=True, text=True)
            trained = time.perf_counter() - start
            if result.returncode != 0:
                print(result.stderr, file=sys.stderr)
                return 1
            summary = json.loads((out / "summary.json").read_text())
            verdict = acceptance_1_6(out / "best.pt", args.workers)
            total = time.perf_counter() - start
        first, info = summary["first_pass"], summary["info"]
        report.update({
            "algo": args.algo, "seed": args.seed, "train_command": " ".join(command[1:]),
            "training_wall_s": round(trained, 1), "iterations": info["iteration"], "env_steps": info["env_steps"],
            "passes_1_6": verdict["passed"], "failed_checks": verdict["failed"],
            "time_to_pass_1_6_s": round(total, 1) if verdict["passed"] else None,
            "wall_s_with_acceptance": round(total, 1),
            "first_tracking_pass": first,
        })
    print(strict_json.dumps(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
