"""Learning curves of one or more training runs (``train.py`` or ``train_sb3.py`` OUT
directories) to one PNG: episode return, fall fraction, mean speed error, and the held-out
acceptance checks' failures and summed speed error, against env steps (top row) and wall time (bottom row).

    scripts/plot_training.py runs/es0 runs/ppo0 runs/sb3_ppo --out docs/images/learning.png
    scripts/plot_training.py runs/es0 --label "ES, sigma 0.02" --out es0.png

Reads each run's ``log.csv`` (one row per iteration) and ``eval.csv`` (the acceptance
evaluations, when there are any); the same numbers TensorBoard shows from ``OUT/tb``.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

from rabbit_msgs_py.cli import ArgumentParser

PANELS = (("episode_return", "log", "episode return"), ("fall_fraction", "log", "fall fraction"),
          ("mean_abs_error", "log", "mean |v̄ - v_d| (m/s)"), ("failures", "eval", "failed acceptance checks"),
          ("total_error", "eval", "acceptance: summed speed error (m/s)"))


def read_rows(path: Path) -> list[dict[str, float]]:
    """A CSV's rows as numbers (a missing or non-numeric cell: NaN; True/False: 1/0)."""
    if not path.is_file():
        return []

    def number(text: str) -> float:
        if text in ("True", "False"):
            return float(text == "True")
        try:
            return float(text)
        except ValueError:
            return float("nan")

    with path.open() as f:
        return [{k: number(v) for k, v in row.items()} for row in csv.DictReader(f)]


def plot(runs: list[tuple[str, Path]], out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(PANELS), figsize=(4.2 * len(PANELS), 6.5), squeeze=False)
    for label, run in runs:
        tables = {"log": read_rows(run / "log.csv"), "eval": read_rows(run / "eval.csv")}
        for column, (key, table, title) in enumerate(PANELS):
            rows = [r for r in tables[table] if key in r]
            for row_index, x_key in enumerate(("env_steps", "wall_s")):
                ax = axes[row_index][column]
                ax.plot([r[x_key] for r in rows], [r[key] for r in rows], marker="o" if table == "eval" else None,
                        markersize=3, label=label)
                ax.set_title(title, fontsize=10)
                ax.set_xlabel("env steps" if x_key == "env_steps" else "wall time (s)")
                ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=8)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(description=__doc__)
    parser.add_argument("runs", nargs="+", type=Path, help="training output directories (log.csv, eval.csv)")
    parser.add_argument("--label", action="append", default=[], help="a legend label per run, in order")
    parser.add_argument("--out", type=Path, default=Path("learning_curves.png"), help="the PNG to write")
    args = parser.parse_args(argv)
    missing = [str(r) for r in args.runs if not (r / "log.csv").is_file()]
    if missing:
        parser.error(f"no log.csv in {', '.join(missing)} (give train.py or train_sb3.py --out directories)")
    if args.label and len(args.label) != len(args.runs):
        parser.error(f"{len(args.label)} --label for {len(args.runs)} runs")
    labels = args.label or [r.name for r in args.runs]
    plot(list(zip(labels, args.runs)), args.out)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
