"""The stable-baselines3 baseline: SB3's PPO (or SAC) on ``RabbitHZD-v0``, the actor our
network's shape, judged by the same acceptance as ``train.py`` and written the same way
(``rabbit_policy.learning.sb3``).

    scripts/train_sb3.py --out runs/sb3_ppo --timesteps 200000
    scripts/train_sb3.py --config config/train/sb3_ppo.yaml --out runs/sb3_ppo
    scripts/train_sb3.py --config config/train/sb3_shipped_ppo.yaml --out runs/sb3_shipped [--resume]
    scripts/walk.py --controller learned --policy-file runs/sb3_ppo/best.pt --speed 1.2

OUT gets ``log.csv``, ``eval.csv``, ``tb/`` (TensorBoard, the tags train.py writes),
``policy.pt`` (the latest actor as our policy file), ``best.pt`` (the evaluated actor with
the fewest failed acceptance checks), ``sb3_model.zip`` (SB3's own save) and ``summary.json``;
every ``--checkpoint-every`` env steps, at the end and on Ctrl-C ``sb3_checkpoint.zip`` and
``sb3_state.json``, which ``--resume`` (the same options) continues from. Any configuration
train.py trains (``--features``, ``--action``, ``--residual-base``, ...): the shipped one is
``config/train/sb3_shipped_ppo.yaml``.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING

from rabbit_msgs_py.cli import ArgumentParser, HelpFormatter, add_config_arguments, config_from_args, \
    refuse_unusable_run_dir

if TYPE_CHECKING:
    from rabbit_policy.learning.sb3 import SB3Config
    from rabbit_policy.parallel import BackendConfig

CHECKPOINT = "sb3_checkpoint.zip"
"""What ``--resume`` continues from (``rabbit_policy.learning.sb3.CHECKPOINT``, named here without its imports)."""


def parse_config(argv: list[str] | None) -> tuple[SB3Config, Path, bool, BackendConfig, bool]:
    """(configuration, output directory, progress bar, evaluation backend, resume) from a
    command line and an optional ``--config`` preset (bad values: one line, exit status 2)."""
    # SB3Config's module imports torch and the environments (2 s): main refuses an unusable
    # --out before they load.
    from rabbit_policy.learning.presets import parse_with_preset
    from rabbit_policy.learning.sb3 import SB3Config
    from rabbit_policy.parallel import add_backend_arguments, backend_config

    parser = ArgumentParser(description=__doc__, formatter_class=HelpFormatter)
    parser.add_argument("--out", type=Path, required=True, help="run directory (new or empty)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--resume", action="store_true", help=f"continue from OUT/{CHECKPOINT} (give the same "
                                                              "options)")
    add_config_arguments(parser, SB3Config)
    add_backend_arguments(parser, workers=False)
    args = parse_with_preset(parser, argv)
    try:
        config = config_from_args(SB3Config, args)
        backend = backend_config(args)
    except ValueError as exc:
        parser.error(str(exc))
    return config, args.out, not args.no_progress, backend, args.resume


def main(argv: list[str] | None = None) -> int:
    refuse_unusable_run_dir(argv, "train_sb3.py", CHECKPOINT)  # before the heavy imports: one line, exit 2
    config, out, progress, backend, resume = parse_config(argv)
    try:
        import stable_baselines3  # noqa: F401  (an optional dependency: requirements-extras.txt)
    except ImportError:
        print("error: train_sb3.py needs stable-baselines3 (pip install -r requirements-extras.txt)", file=sys.stderr)
        return 2
    from rabbit_msgs_py import strict_json
    from rabbit_policy.learning.sb3 import train_sb3

    from rabbit_policy.parallel import BackendUnavailable

    try:
        summary = train_sb3(config, out, progress=progress, backend_config=backend, resume=resume)
    except BackendUnavailable as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(strict_json.dumps(summary))
    return 3 if summary["interrupted"] else 0


if __name__ == "__main__":
    sys.exit(main())
