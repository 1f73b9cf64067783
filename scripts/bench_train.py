#!/usr/bin/env python3
"""Benchmark HZD-RL training: environment throughput and wall time to a passing policy.

    scripts/bench_train.py [--steps 600] [--workers 2] [--train] [--algo ppo|es] [--max-iterations 80]

Prints one JSON object:
* ``env_steps_per_s_per_core``: ``RabbitHZD-v0`` steps (one step = one walking step, about
  0.4-0.7 s of simulation) per second in one process, with the warm-started policy acting
  (network forward included), episodes of the training length, resets included.
* ``sim_seconds_per_s_per_core``: the same in simulated seconds per wall second.
* ``pool_env_steps_per_s``: the same with ``--workers`` processes in parallel (all cores).
* with ``--train``: runs ``scripts/train.py --algo ALGO --stop-when-passed`` with the
  shipped configuration into a temporary directory and reports ``time_to_pass_s`` (wall
  time from the start, warm start and acceptance evaluations included, to the first
  *trained* policy, iteration >= 1, that passes the acceptance checks), iterations and
  env steps then; null if it did not pass within ``--max-iterations``; the best
  evaluation reached (failed checks, iteration, wall time); and ``warm_start_passed``,
  whether the warm-started network already passed before any training.
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

# The configurations of the shipped PPO policy (see its model card) and of the ES result
# reported beside it.
CONFIGS = {
    "ppo": ["--warm-start", "interpolate", "--eval-every", "2", "--envs", "4", "--steps", "128",
            "--ppo-lr", "0.0001", "--target-kl", "0.02", "--init-log-std", "-3.5", "--max-steps", "30"],
    "es": ["--warm-start", "interpolate", "--eval-every", "2", "--pairs", "12", "--sigma", "0.003",
           "--lr", "0.0005", "--episodes", "8", "--max-steps", "30"],
}


def env_throughput(steps: int, seed: int = 0) -> tuple[float, float]:
    """(walking steps per s, simulated s per s) in this process."""
    import torch

    from rabbit_policy.learning.env import RabbitHZDEnv
    from rabbit_policy.runtime.network import HZDPolicyNet
    from rabbit_policy.learning.warm_start import WARM_STARTS, warm_start

    torch.set_num_threads(1)
    torch.manual_seed(seed)
    env = RabbitHZDEnv(max_steps=30)
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


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=600, help="env steps per throughput measurement")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--train", action="store_true", help="also measure the wall time to a passing policy")
    parser.add_argument("--algo", choices=("es", "ppo"), default="ppo")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--max-iterations", type=int, default=80)
    args = parser.parse_args(argv)

    single, sim_rate = env_throughput(args.steps)
    start = time.perf_counter()
    with get_context("fork").Pool(args.workers) as pool:
        rates = pool.map(_worker, [(args.steps, i) for i in range(args.workers)])
    pool_wall = time.perf_counter() - start  # includes the warm starts: use the per-process rates
    report = {
        "env_steps_per_s_per_core": round(single, 1),
        "sim_seconds_per_s_per_core": round(sim_rate, 1),
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
                       str(args.max_iterations), "--stop-when-passed", "--no-progress", *config]
            start = time.perf_counter()
            result = subprocess.run(command, capture_output=True, text=True)
            total = time.perf_counter() - start
            if result.returncode != 0:
                print(result.stderr, file=sys.stderr)
                return 1
            summary = json.loads((out / "summary.json").read_text())
        first, best = summary["first_pass"], summary["best"]
        report.update({
            "algo": args.algo, "seed": args.seed, "train_command": " ".join(command[1:]),
            "time_to_pass_s": None if first is None else first["wall_s"],
            "iterations_to_pass": None if first is None else first["iteration"],
            "env_steps_to_pass": None if first is None else first["env_steps"],
            "training_process_wall_s": round(total, 1),
            "best_failed_checks": None if best is None else best["failures"],
            "best_iteration": None if best is None else best["iteration"],
            "best_wall_s": None if best is None else best["wall_s"],
            "warm_start_passed": summary.get("warm_start", {}).get("passed"),
        })
    print(strict_json.dumps(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
