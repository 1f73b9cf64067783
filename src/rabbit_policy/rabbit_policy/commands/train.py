"""Train the HZD-RL policy on ``RabbitHZD-v0`` with Evolution Strategies or PPO.

    scripts/train.py --algo es --out runs/es0             # the first shipped run (the defaults)
    scripts/train.py --algo ppo --out runs/ppo0 --iterations 200
    scripts/train.py ... --resume                          # continue from OUT/checkpoint.pt
    scripts/train.py --config config/train/shipped_es.yaml --out runs/X   # a preset (rl-zoo style)

Every option is a field of one configuration dataclass, its default and help written once
there (as CleanRL's ``Args``): the run's ``TrainingConfig`` (``rabbit_policy.learning.
training``), the episodes' ``EpisodeConfig`` (``learning.env``) and the algorithm's
``ESConfig`` (``learning.es``) or ``PPOConfig`` (``learning.ppo``). The defaults are the
first shipped run (``config/train/first_shipped_es.yaml``); the policy shipped now was
trained with ``--config config/train/shipped_es.yaml`` (its model card's command). The training loop is
``rabbit_policy.learning.training`` (its docstring: the warm start, ES and PPO, and what OUT
holds: ``log.csv``, ``eval.csv``, ``policy.pt``, ``best.pt``, ``checkpoint.pt``,
``summary.json``).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING

from rabbit_msgs_py.cli import ArgumentParser, HelpFormatter, add_config_arguments, config_from_args, \
    refuse_unusable_run_dir

if TYPE_CHECKING:
    from rabbit_policy.learning.training import TrainingConfig

ALGORITHMS = ("es", "ppo")


def build_parser() -> ArgumentParser:
    # The configuration classes import torch and the environments (2-3 s): main refuses an
    # unusable --out before they load.
    from rabbit_policy.learning.env import EpisodeConfig
    from rabbit_policy.learning.es import ESConfig
    from rabbit_policy.learning.ppo import PPOConfig
    from rabbit_policy.learning.training import TrainingConfig
    from rabbit_policy.parallel import add_backend_arguments

    parser = ArgumentParser(description=__doc__, formatter_class=HelpFormatter)
    parser.add_argument("--algo", choices=ALGORITHMS, required=True, help="the trainer")
    parser.add_argument("--out", type=Path, required=True, help="run directory (new, or --resume)")
    add_config_arguments(parser, TrainingConfig)
    add_backend_arguments(parser, workers=False)
    add_config_arguments(parser.add_argument_group("episodes (ES and PPO)"), EpisodeConfig)
    add_config_arguments(parser.add_argument_group("ES"), ESConfig)
    add_config_arguments(parser.add_argument_group("PPO"), PPOConfig)
    return parser


def parse_config(argv: list[str] | None) -> TrainingConfig:
    """The run's configuration from a command line and an optional ``--config`` preset
    (``rabbit_policy.learning.presets``; bad values: one line, exit status 2)."""
    from rabbit_policy.learning.es import ESConfig
    from rabbit_policy.learning.ppo import PPOConfig
    from rabbit_policy.learning.presets import parse_with_preset
    from rabbit_policy.learning.training import TrainingConfig
    from rabbit_policy.parallel import backend_config

    parser = build_parser()
    args = parse_with_preset(parser, argv)
    try:
        trainer = (config_from_args(ESConfig, args, workers=args.workers) if args.algo == "es"
                   else config_from_args(PPOConfig, args))
        return config_from_args(TrainingConfig, args, algo=args.algo, out=args.out, trainer=trainer,
                                backend=backend_config(args))
    except ValueError as exc:
        parser.error(str(exc))


def main(argv: list[str] | None = None) -> int:
    refuse_unusable_run_dir(argv, "train.py", "checkpoint.pt")  # before the heavy imports: one line, exit 2
    config = parse_config(argv)
    from rabbit_policy.learning.training import train

    return train(config)


if __name__ == "__main__":
    sys.exit(main())
