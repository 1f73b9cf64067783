#!/usr/bin/env python3
"""Train the HZD-RL policy on ``RabbitHZD-v0`` with Evolution Strategies or PPO.

    scripts/train.py --algo es  --seed 0 --workers 2 --out runs/es0 [--iterations 60]
    scripts/train.py --algo ppo --seed 0 --workers 2 --out runs/ppo0 [--iterations 200]
    scripts/train.py ... --resume          # continue from OUT/checkpoint.pt

The training loop is ``rabbit_policy.learning.training`` (its docstring: the warm start,
ES and PPO, and what OUT holds: ``log.csv``, ``eval.csv``, ``policy.pt``, ``best.pt``,
``checkpoint.pt``, ``summary.json``). ``--stop-when-passed`` ends training at the first
passing evaluation of a trained policy.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rabbit_msgs_py.cli import ArgumentParser
from rabbit_policy.parallel import add_backend_arguments, backend_config


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--algo", choices=("es", "ppo"), required=True)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workers", type=int, default=2, help="processes for rollouts and evaluation")
    parser.add_argument("--out", type=Path, required=True)
    add_backend_arguments(parser)
    parser.add_argument("--iterations", "--generations", type=int, default=60, dest="iterations",
                        help="ES generations / PPO iterations in all (including resumed ones)")
    parser.add_argument("--max-steps", type=int, default=40, help="walking steps per training episode")
    parser.add_argument("--decision-period", type=int, default=0, metavar="TICKS",
                        help="0: one env step per walking step (the gait for the next step); N > 0: every N "
                             "ticks, the gait applied at once (the policy then runs that way everywhere)")
    parser.add_argument("--distribution", choices=("paper", "broad"), default="paper",
                        help="episodes: the paper's (one command change) or broad (commands every 2-5 s, "
                             "pushes, model errors, torque delays); rabbit_policy.learning.env.DISTRIBUTIONS")
    parser.add_argument("--fall-penalty", type=float, default=-10.0,
                        help="reward once when an episode ends by a fall or stall (<= 0)")
    parser.add_argument("--checkpoint-every", type=int, default=5)
    parser.add_argument("--eval-every", type=int, default=2, help="acceptance check period (0: never)")
    parser.add_argument("--stop-when-passed", action="store_true")
    parser.add_argument("--warm-start", choices=("scheduled", "nearest", "interpolate", "feedback", "none"), default="scheduled",
                        help="fit the network to the classic library first (rabbit_policy.learning.warm_start)")
    parser.add_argument("--no-progress", action="store_true", help="plain lines instead of a progress bar")
    parser.add_argument("--resume", action="store_true")
    es = parser.add_argument_group("ES")
    es.add_argument("--pairs", type=int, default=8, help="antithetic pairs per generation")
    es.add_argument("--sigma", type=float, default=0.02, help="perturbation std (parameter units)")
    es.add_argument("--lr", type=float, default=0.01, help="Adam step size")
    es.add_argument("--episodes", type=int, default=8, help="episodes per population member")
    ppo = parser.add_argument_group("PPO")
    ppo.add_argument("--envs", type=int, default=None, help="parallel environments (default: 2 x workers)")
    ppo.add_argument("--steps", type=int, default=128, help="steps per environment per iteration")
    ppo.add_argument("--epochs", type=int, default=10)
    ppo.add_argument("--minibatches", type=int, default=4)
    ppo.add_argument("--ppo-lr", type=float, default=1e-4)
    ppo.add_argument("--target-kl", type=float, default=0.02, help="early stop of the epochs (0: off)")
    ppo.add_argument("--gae-lambda", type=float, default=0.95)
    ppo.add_argument("--gamma", type=float, default=0.99, help="discount (the paper: 0.99)")
    ppo.add_argument("--init-log-std", type=float, default=-3.5, help="initial log std (normalised units)")
    args = parser.parse_args(argv)
    if min(args.workers, args.iterations, args.max_steps, args.checkpoint_every) < 1 or args.eval_every < 0:
        parser.error("--workers, --iterations, --max-steps, --checkpoint-every must be >= 1, --eval-every >= 0")
    if args.decision_period < 0:
        parser.error("--decision-period must be >= 0 ticks")
    if not args.fall_penalty <= 0.0:
        parser.error("--fall-penalty must be <= 0")
    if args.envs is None:
        args.envs = 2 * args.workers
    try:
        args.backend_config = backend_config(args)
    except ValueError as exc:
        parser.error(str(exc))
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    from rabbit_policy.learning.training import TrainingConfig, train

    if args.algo == "es":
        from rabbit_policy.learning.es import ESConfig

        trainer = ESConfig(pairs=args.pairs, sigma=args.sigma, lr=args.lr, episodes=args.episodes,
                           max_steps=args.max_steps, seed=args.seed, workers=args.workers,
                           decision_period=args.decision_period, distribution=args.distribution,
                           fall_penalty=args.fall_penalty)
    else:
        from rabbit_policy.learning.ppo import PPOConfig

        trainer = PPOConfig(envs=args.envs, steps=args.steps, epochs=args.epochs, minibatches=args.minibatches,
                            lr=args.ppo_lr, init_log_std=args.init_log_std, target_kl=args.target_kl or None,
                            gae_lambda=args.gae_lambda, gamma=args.gamma, max_steps=args.max_steps, seed=args.seed,
                            decision_period=args.decision_period, distribution=args.distribution,
                            fall_penalty=args.fall_penalty)
    return train(TrainingConfig(algo=args.algo, out=args.out, trainer=trainer, workers=args.workers,
                                iterations=args.iterations, checkpoint_every=args.checkpoint_every,
                                eval_every=args.eval_every, stop_when_passed=args.stop_when_passed,
                                warm_start=args.warm_start, no_progress=args.no_progress, resume=args.resume,
                                backend=args.backend_config))


if __name__ == "__main__":
    sys.exit(main())
