#!/usr/bin/env python3
"""Ship a trained HZD-RL policy as ``rabbit_policy``'s package data, with a model card.

    scripts/ship_policy.py runs/es0/best.pt [--compare runs/ppo0/best.pt ...] [--dry-run]

Runs the acceptance checks (``rabbit_policy.evaluation.acceptance``) on the policy file, and on each
``--compare`` file, the network the run started from (its warm start, rebuilt: what
training added) and the classic HZD library for the card's evaluation table, then copies
the file to ``src/rabbit_policy/rabbit_policy/trained/hzd_rl_policy.pt`` and writes
``MODEL_CARD.md`` and ``evaluation.json`` (every figure of the table) beside it (algorithm, seed, workers, training time and steps from the
checkpoint's ``info``, the evaluation table). Refuses a policy that fails the checks unless
``--allow-failing``. ``--dry-run`` prints the card without writing anything.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

from rabbit_msgs_py import strict_json
from rabbit_msgs_py.cli import ArgumentParser

ROOT = Path(__file__).resolve().parents[1]
TARGET = ROOT / "src" / "rabbit_policy" / "rabbit_policy" / "trained"


def fmt(value, digits: int = 3) -> str:
    return "—" if value is None else f"{value:.{digits}f}"


def evaluation_table(results: list[tuple[str, dict]]) -> list[str]:
    """Markdown rows: per controller, the constant-speed errors and the schedule reach times."""
    speeds = [c["speed"] for c in results[0][1]["constant"]]
    lines = ["Constant speed, 30 s (mean hip speed over the last 15 s minus the command, m/s; "
             "`fell` if it fell):", "",
             "| controller | " + " | ".join(f"{v:.1f}" for v in speeds) + " |",
             "|---|" + "---|" * len(speeds)]
    for name, result in results:
        cells = ["fell" if c["fell"] else f"{c['error']:+.3f}" for c in result["constant"]]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    schedule = results[0][1]["schedule"]["segments"]
    lines += ["", "Speed schedule 0.8 → 1.2 → 0.9 → 1.5 → 0.7 m/s, 10 s each (seconds to the first "
              "one-step average within 0.05 m/s; goal ≤ 4 s):", "",
              "| controller | " + " | ".join(f"{s['command']:.1f}" for s in schedule) + " | fell | passed |",
              "|---|" + "---|" * (len(schedule) + 2)]
    for name, result in results:
        cells = [fmt(s["reach_time"], 2) for s in result["schedule"]["segments"]]
        lines.append(f"| {name} | " + " | ".join(cells) +
                     f" | {result['schedule']['fell']} | {'yes' if result['passed'] else 'no'} |")
    return lines


CLI_FLAGS = {  # training configuration key -> scripts/train.py flag
    "es": {"pairs": "--pairs", "sigma": "--sigma", "lr": "--lr", "episodes": "--episodes",
           "max_steps": "--max-steps"},
    "ppo": {"envs": "--envs", "steps": "--steps", "epochs": "--epochs", "minibatches": "--minibatches",
            "lr": "--ppo-lr", "gamma": "--gamma", "gae_lambda": "--gae-lambda", "target_kl": "--target-kl",
            "init_log_std": "--init-log-std", "max_steps": "--max-steps"},
}


def train_command(info: dict) -> str:
    """The ``scripts/train.py`` command line that reproduces a checkpoint (deterministic
    for the seed and worker count; ``best.pt`` also depends on ``--eval-every``)."""
    algo = info.get("algorithm")
    parts = ["scripts/train.py", "--algo", str(algo), "--seed", str(info.get("seed")), "--workers",
             str(info.get("workers")), "--warm-start", str(info.get("warm_start")), "--iterations",
             str(info.get("iteration"))]
    if info.get("eval_every") is not None:
        parts += ["--eval-every", str(info["eval_every"])]
    for key, flag in CLI_FLAGS.get(algo, {}).items():
        value = info.get("config", {}).get(key)
        if value is not None:
            parts += [flag, str(value)]
    return " ".join(parts + ["--out", "runs/X"])


def model_card(info: dict, results: list[tuple[str, dict]]) -> str:
    cfg = info.get("config", {})
    lines = [
        "# HZD-RL policy shipped with rabbit_policy", "",
        "`hzd_rl_policy.pt`: the paper's network (3 → 12 → 12 → 12 → 21, tanh, sigmoid output "
        f"scaled to the action bounds, {info.get('parameters', 633)} parameters: 20 free Bezier "
        "coefficients + Kd). Inputs: commanded speed, the last step's mean hip speed and mean "
        "speed error (m/s). Output: the gait for the next step. Loaded by default by "
        "`policy_node` (`policy:=learned`) and `scripts/walk.py --controller learned`.", "",
        "## Training", "",
        f"- algorithm: **{info.get('algorithm')}**, seed {info.get('seed')}, workers {info.get('workers')}, "
        f"warm start from the classic gait library: {info.get('warm_start')}",
        f"- iterations: {info.get('iteration')}, environment steps (walking steps): {info.get('env_steps')}, "
        f"wall time: {info.get('wall_s')} s on the machine that trained it",
        f"- configuration: `{strict_json.dumps(cfg)}`",
        "- environment: `RabbitHZD-v0` (one env step = one walking step; reward −(v̄ − v_d)², "
        "fall penalty −10; v_d uniform in [0.7, 1.5] m/s, changed once per episode)",
        f"- regenerate: `{train_command(info)}`, then `scripts/ship_policy.py runs/X/best.pt` "
        "(this file is that run's `best.pt`: the evaluated iteration with the fewest failed "
        "acceptance checks)",
        "", "## Evaluation (ROS-free fast path, `rabbit_policy.evaluation.acceptance`)", "",
        *evaluation_table(results), "",
        "Limits: trained and evaluated on the `paper` model only (not `drives`), flat ground, "
        "no sensor noise or delay beyond the one-step decision latency.", "",
    ]
    return "\n".join(lines)


def warm_start_policy(checkpoint):
    """The network the run started from (its warm start, rebuilt from the checkpoint's
    seed and bounds; deterministic), or None if it started from random weights."""
    import torch

    from rabbit_policy.runtime.gait_library import GaitLibrary
    from rabbit_policy.runtime.policies import NetworkPolicy
    from rabbit_policy.learning.warm_start import WARM_STARTS, initial_network

    name = checkpoint.info.get("warm_start")
    if name not in WARM_STARTS:
        return None
    torch.set_num_threads(1)  # as scripts/train.py
    net, _ = initial_network(checkpoint.low, checkpoint.high, GaitLibrary.load(),
                             int(checkpoint.info.get("seed", 0)), name)
    return NetworkPolicy(net, f"warm start ({name})")


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("policy", type=Path)
    parser.add_argument("--compare", type=Path, nargs="*", default=[], help="more policy files for the table")
    parser.add_argument("--allow-failing", action="store_true")
    parser.add_argument("--dry-run", action="store_true")
    args = parser.parse_args(argv)

    from rabbit_policy.evaluation.acceptance import acceptance
    from rabbit_policy.runtime.policies import PolicyUnavailable, make_policy

    try:
        policy = make_policy("learned", policy_file=args.policy)
        others = [make_policy("learned", policy_file=p) for p in args.compare]
    except PolicyUnavailable as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    info = policy.checkpoint.info
    results = [(f"HZD-RL ({info.get('algorithm')}, shipped)", acceptance(policy))]
    for other in others:
        results.append((f"HZD-RL ({other.checkpoint.info.get('algorithm')})", acceptance(other)))
    start = warm_start_policy(policy.checkpoint)
    if start is not None:
        results.append((f"warm start only ({info.get('warm_start')}, untrained)", acceptance(start)))
    for mode in ("nearest", "interpolate"):
        results.append((f"classic HZD ({mode})", acceptance(make_policy("classic", mode=mode))))
    card = model_card(info, results)
    print(card)
    if not results[0][1]["passed"] and not args.allow_failing:
        print("error: the policy fails the acceptance checks; not shipped (--allow-failing to override)",
              file=sys.stderr)
        return 1
    if not args.dry_run:
        TARGET.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(args.policy, TARGET / "hzd_rl_policy.pt")
        (TARGET / "MODEL_CARD.md").write_text(card)
        (TARGET / "evaluation.json").write_text(strict_json.dumps(dict(results), indent=1) + "\n")
        print(f"shipped to {TARGET / 'hzd_rl_policy.pt'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
