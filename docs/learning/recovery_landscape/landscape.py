# Is the push-recovery return a lottery in the parameters too? (docs/learning.md, 2026-11-27 (later))
#   .venv/bin/python docs/learning/recovery_landscape/landscape.py > docs/learning/recovery_landscape/landscape.json
# The recovery preset's episodes (config/train/recovery_residual_es.yaml: a residual on the recovery
# controller, a push at a phase of a step in every episode, 0.8-2.2x classic's margin) are drawn once
# (24 episodes, ES's stratified draw, seed 0) and kept. The zero residual (the recovery controller) and
# 12 random parameter perturbations of each size sigma (ES's: theta + sigma * N(0, I)) walk all of them.
# For each sigma: the perturbed members' mean returns (mean and spread), and how many of the 24 episodes
# end otherwise (fell/stalled against walked) than at the zero residual, per member. If tiny sigmas
# already flip episodes, the ranks ES and ARS compute follow those flips, not a direction.
import importlib.util
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[3]
SIGMAS = (0.001, 0.003, 0.01, 0.03)
MEMBERS = 12


def training_config(preset: str = "recovery_residual_es.yaml"):
    spec = importlib.util.spec_from_file_location("train_script", ROOT / "scripts" / "train.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.parse_config(["--config", str(ROOT / "config/train" / preset),
                                "--out", "/tmp/unused", "--episodes", "24"])


def setup(preset: str = "recovery_residual_es.yaml"):
    """(the preset's ES config, the zero-residual network, its flat parameters, the 24 episodes,
    the generator after drawing them): what every script here starts from."""
    from rabbit_policy.learning.es import get_flat, stratified_episodes
    from rabbit_policy.learning.warm_start import zero_residual_network
    from rabbit_policy.runtime.actions import policy_bounds
    from rabbit_policy.runtime.gait_library import GaitLibrary
    from rabbit_policy.runtime.memory import INPUTS

    config = training_config(preset).trainer
    bounds = policy_bounds("residual", GaitLibrary.load())
    net = zero_residual_network(bounds.low, bounds.high, INPUTS[config.features], 0)
    rng = np.random.default_rng(0)
    episodes = stratified_episodes(rng, config.episodes, (0.7, 1.5))
    return config, net, get_flat(net), episodes, rng


def main() -> None:
    from rabbit_policy.learning.es import _evaluate

    config, _net, theta, episodes, rng = setup()
    key = tuple(sorted(config.env_kwargs().items()))
    centre = _evaluate((key, theta, episodes))
    fell0 = np.array([r.fell for r in centre])
    rows = {"episodes": len(episodes), "centre": {"mean_return": float(np.mean([r.total for r in centre])),
                                                   "failed": int(fell0.sum())}, "sigmas": []}
    for sigma in SIGMAS:
        means, flips, failed = [], [], []
        for _ in range(MEMBERS):
            member = _evaluate((key, theta + sigma * rng.standard_normal(theta.size), episodes))
            fell = np.array([r.fell for r in member])
            means.append(float(np.mean([r.total for r in member])))
            flips.append(int((fell != fell0).sum()))
            failed.append(int(fell.sum()))
        rows["sigmas"].append({"sigma": sigma, "mean_return": float(np.mean(means)), "std_return": float(np.std(means)),
                               "flipped_per_member": flips, "failed_per_member": failed})
        print(f"sigma {sigma}: flips {flips}", file=sys.stderr, flush=True)
    print(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
