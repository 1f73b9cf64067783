#!/usr/bin/env python3
"""Train the HZD-RL policy on ``RabbitHZD-v0``.

    scripts/train.py --algo es --seed 0 --workers 2 --out runs/es0 [--generations 100] [--resume]

ES (``rabbit_policy.es``): the network is first warm-started on the classic gait library
(``rabbit_policy.warm_start``, a few seconds), then improved by antithetic ES with centred
ranks. Each generation appends a row to ``OUT/log.csv`` (generation, wall time, env
steps, population mean/best return, the return of the generation's starting parameters)
and prints a progress line; ``OUT/checkpoint.pt`` (policy + optimiser state) is written
every ``--checkpoint-every`` generations and at the end, ``OUT/policy.pt`` holds the
policy alone (the file ``policy_node`` loads with ``policy_file``). ``--resume``
continues from ``OUT/checkpoint.pt``. Deterministic for a given seed and worker count.
PPO arrives with the rest of the learning issue.
"""

from __future__ import annotations

import argparse
import csv
import json
import signal
import sys
import time
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--algo", choices=("es",), default="es")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--generations", type=int, default=100)
    parser.add_argument("--pairs", type=int, default=16)
    parser.add_argument("--sigma", type=float, default=0.02)
    parser.add_argument("--lr", type=float, default=0.01)
    parser.add_argument("--episodes", type=int, default=2)
    parser.add_argument("--max-steps", type=int, default=40)
    parser.add_argument("--checkpoint-every", type=int, default=5)
    parser.add_argument("--resume", action="store_true")
    args = parser.parse_args(argv)
    if args.workers < 1 or args.generations < 1:
        parser.error("--workers and --generations must be >= 1")

    import numpy as np
    import torch

    from rabbit_policy.env import RabbitHZDEnv
    from rabbit_policy.es import Adam, ESConfig, EvolutionStrategy, set_flat
    from rabbit_policy.network import HZDPolicyNet, PolicyCheckpoint
    from rabbit_policy.warm_start import warm_start

    out: Path = args.out
    checkpoint_path = out / "checkpoint.pt"
    if out.exists() and not args.resume and any(out.iterdir()):
        parser.error(f"{out} is not empty; use --resume or another --out")
    out.mkdir(parents=True, exist_ok=True)
    config = ESConfig(pairs=args.pairs, sigma=args.sigma, lr=args.lr, episodes=args.episodes,
                      max_steps=args.max_steps, seed=args.seed, workers=args.workers)
    torch.manual_seed(args.seed)
    env = RabbitHZDEnv(max_steps=args.max_steps)
    net = HZDPolicyNet(env.bounds.low, env.bounds.high)
    start_wall = time.perf_counter()
    elapsed_before = 0.0
    if args.resume:
        if not checkpoint_path.is_file():
            parser.error(f"--resume: no {checkpoint_path}")
        state = torch.load(checkpoint_path, map_location="cpu", weights_only=False)
        net.load_state_dict(state["state_dict"])
    else:
        mse = warm_start(net, env.library, seed=args.seed)
        print(f"warm start on the classic gait library: mse {mse:.2e} (normalised action units)", flush=True)
    es = EvolutionStrategy(net, config)
    if args.resume:
        es.theta = np.asarray(state["theta"])
        set_flat(net, es.theta)
        es.rng.bit_generator.state = state["rng"]
        es.adam = Adam(**state["adam"])
        es.generation, es.env_steps = state["generation"], state["env_steps"]
        elapsed_before = state["wall_s"]

    def save() -> None:
        wall = elapsed_before + time.perf_counter() - start_wall
        torch.save({"state_dict": net.state_dict(), "theta": es.theta.tolist(), "rng": es.rng.bit_generator.state,
                    "adam": {"lr": es.adam.lr, "t": es.adam.t, "m": es.adam.m, "v": es.adam.v},
                    "generation": es.generation, "env_steps": es.env_steps, "wall_s": wall,
                    "config": config.to_dict()}, checkpoint_path)
        info = {"algorithm": "es", "seed": args.seed, "workers": args.workers, "generation": es.generation,
                "env_steps": es.env_steps, "wall_s": wall, "config": config.to_dict()}
        PolicyCheckpoint(net.state_dict(), env.bounds.low, env.bounds.high, info).save(out / "policy.pt")

    def interrupt(_signum, _frame):
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, interrupt)  # SIGTERM saves a checkpoint like Ctrl-C
    log_path = out / "log.csv"
    new_log = not log_path.exists()
    try:
        with log_path.open("a", newline="") as f:
            writer = csv.writer(f)
            if new_log:
                writer.writerow(["generation", "wall_s", "env_steps", "population_mean", "population_best",
                                 "policy_return"])
            while es.generation < args.generations:
                stats = es.step()
                wall = elapsed_before + time.perf_counter() - start_wall
                writer.writerow([stats["generation"], f"{wall:.1f}", stats["env_steps"], stats["population_mean"],
                                 stats["population_best"], stats["policy_return"]])
                f.flush()
                print(f"gen {stats['generation']:4d}/{args.generations}  {wall:7.1f} s  "
                      f"steps {stats['env_steps']:8d}  mean {stats['population_mean']:8.3f}  "
                      f"best {stats['population_best']:8.3f}  policy {stats['policy_return']:8.3f}", flush=True)
                if stats["generation"] % args.checkpoint_every == 0:
                    save()
    except KeyboardInterrupt:
        print("interrupted: saving a checkpoint", file=sys.stderr)
    finally:
        save()
        es.close()
    print(json.dumps({"out": str(out), "generation": es.generation, "env_steps": es.env_steps}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
