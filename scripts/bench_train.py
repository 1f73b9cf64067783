#!/usr/bin/env python3
"""Benchmark HZD-RL training: environment throughput and wall time to a passing policy.

    scripts/bench_train.py [--steps 600] [--workers 2] [--train] [--algo es|ppo] [--max-iterations 60]

Prints one JSON object:
* ``env_steps_per_s_per_core``: ``RabbitHZD-v0`` steps per second in one process with the
  shipped decision rate (one step = 20 ticks = 20 ms of simulation; the paper's episodes),
  the warm-started policy acting (network forward included), resets included;
  ``per_walking_step`` the same with one env step per walking step (0.4-0.7 s).
* ``sim_seconds_per_s_per_core``: the same in simulated seconds per wall second.
* ``pool_env_steps_per_s``: the same with ``--workers`` processes in parallel (all cores).
* with ``--train``: runs ``scripts/train.py`` with the shipped configuration (:data:`CONFIGS`)
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
import subprocess
import sys
import tempfile
import time
from multiprocessing import get_context
from pathlib import Path

from rabbit_msgs_py import strict_json
from rabbit_msgs_py.cli import ArgumentParser

ROOT = Path(__file__).resolve().parents[1]

# The configurations of the shipped ES policy (see its model card) and of the PPO result
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
    from rabbit_policy.runtime.network import HZDPolicyNet
    from rabbit_policy.learning.warm_start import WARM_STARTS, warm_start

    torch.set_num_threads(1)
    torch.manual_seed(seed)
    env = RabbitHZDEnv(max_steps=500 if decision_period else 30, decision_period=decision_period)
    net = HZDPolicyNet(env.bounds.low, env.bounds.high)
    warm_start(net, env.library, seed=seed, config=WARM_STARTS["interpolate"])
    obs, _ = env.reset(seed=seed)
    sim_time, episode_start = 0.0, 0.0
    start = time.perf_counter()
    for _ in range(steps):
        with torch.no_grad():
            action = net(torch.as_tensor(obs)).numpy()
        obs, _r, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            sim_time += info["time"]
            obs, _ = env.reset()
            episode_start = 0.0
        else:
            episode_start = info["time"]
    wall = time.perf_counter() - start
    return steps / wall, (sim_time + episode_start) / wall


def _worker(args: tuple[int, int]) -> tuple[float, float]:
    return env_throughput(*args)


def acceptance_1_6(policy_file: Path, workers: int) -> dict:
    """The learning issue's checks 1-6 on a policy file (the full broad evaluation)."""
    from rabbit_policy.evaluation.acceptance import broad_acceptance
    from rabbit_policy.runtime.policies import make_policy

    with get_context("fork").Pool(workers) as pool:
        return broad_acceptance(make_policy("learned", policy_file=policy_file), make_policy("classic"),
                                map_fn=pool.map)


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=600, help="env steps per throughput measurement")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--train", action="store_true", help="also measure the wall time to a passing policy")
    parser.add_argument("--algo", choices=("es", "ppo"), default="es")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--max-iterations", type=int, default=60)
    args = parser.parse_args(argv)

    single, sim_rate = env_throughput(args.steps)
    per_step, per_step_sim = env_throughput(max(args.steps // 20, 30), decision_period=0)
    start = time.perf_counter()
    with get_context("fork").Pool(args.workers) as pool:
        rates = pool.map(_worker, [(args.steps, i) for i in range(args.workers)])
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
    if args.train:
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "run"
            config = CONFIGS[args.algo]
            command = [sys.executable, str(ROOT / "scripts" / "train.py"), "--algo", args.algo, "--seed",
                       str(args.seed), "--workers", str(args.workers), "--out", str(out), "--iterations",
                       str(args.max_iterations), "--no-progress", *config]
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
