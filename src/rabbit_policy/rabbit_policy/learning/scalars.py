"""TensorBoard scalars of a training run, under the same tags for our ES, our PPO and the
stable-baselines3 baseline (``scripts/train_sb3.py``), so their curves overlay in one
TensorBoard (``tensorboard --logdir runs``), against env steps:

| tag | what |
|-----|------|
| ``rollout/episode_return`` | mean undiscounted return of the iteration's episodes (ES: the parameters it started from) |
| ``rollout/fall_fraction`` | share of those episodes that ended by a fall or stall |
| ``rollout/mean_abs_error`` | mean \\|v̄ - v_d\\| per env step (m/s) |
| ``eval/failed_checks``, ``eval/total_error``, ``eval/worst_speed_error``, ``eval/falls``, ``eval/passed`` | the acceptance evaluation (``eval.csv``'s columns) |
| ``time/wall_s`` | wall time of the run (s) |
| ``<algo>/<statistic>`` | the algorithm's own statistics (``log.csv``'s other columns: ``es/population_mean``, ``ppo/approx_kl``, ...) |

The same numbers are in ``log.csv`` and ``eval.csv`` (``scripts/plot_training.py`` draws them).
Without the ``tensorboard`` package (pip only, in requirements.txt) a run says so once and
writes the CSV files alone.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

SHARED = {"episode_return": "rollout/episode_return", "fall_fraction": "rollout/fall_fraction",
          "mean_abs_error": "rollout/mean_abs_error"}
EVALUATION = {"failures": "eval/failed_checks", "total_error": "eval/total_error",
              "worst_speed_error": "eval/worst_speed_error", "falls": "eval/falls", "passed": "eval/passed"}
NOT_SCALARS = ("iteration", "env_steps", "wall_s")


class TrainingScalars:
    """Writes a run's scalars to ``directory`` (TensorBoard event files; appended to on resume)."""

    def __init__(self, directory: Path, algorithm: str) -> None:
        self.algorithm = algorithm
        try:
            from torch.utils.tensorboard import SummaryWriter
        except ImportError:
            print("note: no TensorBoard scalars (pip install tensorboard); log.csv and eval.csv hold the same",
                  file=sys.stderr)
            self.writer = None
            return
        self.writer = SummaryWriter(log_dir=str(directory))

    def _add(self, tag: str, value, step: int) -> None:
        if self.writer is None:
            return
        if isinstance(value, bool):
            value = float(value)
        if isinstance(value, (int, float)) and math.isfinite(value):
            self.writer.add_scalar(tag, float(value), global_step=step)

    def iteration(self, stats: dict, wall_s: float) -> None:
        """One training iteration's statistics (a ``log.csv`` row; ``env_steps`` is the x axis)."""
        step = int(stats["env_steps"])
        for key, value in stats.items():
            if key not in NOT_SCALARS:
                self._add(SHARED.get(key, f"{self.algorithm}/{key}"), value, step)
        self._add("time/wall_s", wall_s, step)
        if self.writer is not None:
            self.writer.flush()

    def evaluation(self, row: dict) -> None:
        """One acceptance evaluation (an ``eval.csv`` row)."""
        for key, tag in EVALUATION.items():
            self._add(tag, row.get(key), int(row["env_steps"]))
        if self.writer is not None:
            self.writer.flush()

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
