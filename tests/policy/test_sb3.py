"""The stable-baselines3 baseline (``scripts/train_sb3.py``): a short PPO run on RabbitHZD-v0
writes what train.py writes, its actor exported to our policy file acts exactly as SB3's
deterministic policy, and walk.py walks it."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

import rabbit_policy  # noqa: F401  (registers RabbitHZD-v0)
from rabbit_policy.learning.env import ActionBounds
from rabbit_policy.learning.sb3 import SB3Config, build_model, export_actor, warm_start_actor
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.network import PolicyCheckpoint
from rabbit_policy.spec.make import make_policy

pytestmark = pytest.mark.sim

ROOT = Path(__file__).resolve().parents[2]


def test_the_sb3_presets_parse(tmp_path):
    import importlib

    script = importlib.import_module("rabbit_policy.commands.train_sb3")
    presets = sorted((ROOT / "config" / "train").glob("sb3*.yaml"))
    assert presets
    for path in presets:
        config, out, _, _, resume = script.parse_config(["--config", str(path), "--out", str(tmp_path / "x")])
        assert not resume
        assert config.algo in ("ppo", "sac") and out == tmp_path / "x"


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_the_exported_actor_acts_as_sb3s_deterministic_policy(algo):
    from stable_baselines3.common.env_util import make_vec_env

    config = SB3Config(algo=algo, envs=1, max_steps=5, decision_period=20, distribution="paper")
    env = make_vec_env(lambda: gym.make("RabbitHZD-v0", **config.env_kwargs()), n_envs=1, seed=0)
    model = build_model(config, env)
    bounds = ActionBounds.from_library(GaitLibrary.load())
    if algo == "ppo":  # the warm start (12 s on a slow machine) is the same code for both actors
        mse = warm_start_actor(model, config, bounds.low, bounds.high)
        assert mse < 1e-3  # the classic library, as our runs start
    net = export_actor(model, algo, bounds.low, bounds.high, {}).network()
    rng = np.random.default_rng(0)
    obs = np.column_stack([rng.uniform(0.7, 1.5, 50), rng.uniform(0.4, 1.8, 50), rng.uniform(-0.5, 0.5, 50)])
    theirs, _ = model.predict(obs.astype(np.float32), deterministic=True)  # normalised, in [-1, 1]
    with torch.no_grad():
        ours = net(torch.as_tensor(obs, dtype=torch.float32)).numpy()
    assert np.allclose(bounds.to_normalised(ours), theirs, atol=2e-5)
    env.close()


@pytest.mark.slow
def test_a_short_sb3_ppo_run_logs_like_train_py_and_its_policy_walks(tmp_path):
    out = tmp_path / "sb3"
    run = subprocess.run([sys.executable, "scripts/train_sb3.py", "--out", str(out), "--timesteps", "1024",
                          "--envs", "2", "--n-steps", "256", "--max-steps", "100", "--decision-period", "20",
                          "--distribution", "paper", "--log-every", "512", "--eval-every", "0",
                          "--no-progress"], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    summary = json.loads(run.stdout.strip().splitlines()[-1])
    assert summary["info"]["env_steps"] == 1024 and summary["best"] is not None
    with (out / "log.csv").open() as f:
        log = list(csv.DictReader(f))
    assert [int(r["env_steps"]) for r in log] == [512, 1024] and all(np.isfinite(float(r["mean_abs_error"]))
                                                                      for r in log)
    assert [line.split(":")[0] for line in run.stderr.splitlines() if line.startswith("iteration ")] == [
        "iteration 1", "iteration 2"]  # progress per iteration, with --no-progress too
    with (out / "eval.csv").open() as f:
        assert [int(r["env_steps"]) for r in csv.DictReader(f)] == [1024]  # --eval-every 0: at the end only
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(out / "tb"))
    events.Reload()
    assert {"rollout/episode_return", "rollout/fall_fraction", "eval/failed_checks"} <= set(events.Tags()["scalars"])
    assert (out / "sb3_model.zip").is_file()
    checkpoint = PolicyCheckpoint.load(out / "best.pt")
    assert checkpoint.info["algorithm"] == "sb3_ppo" and checkpoint.info["output"] == "clip"
    assert make_policy("learned", policy_file=out / "best.pt").decision_period == 20  # as trained
    walked = subprocess.run([sys.executable, "scripts/walk.py", "--controller", "learned", "--policy-file",
                             str(out / "best.pt"), "--speed", "1.0", "--duration", "4", "--json"], cwd=ROOT,
                            capture_output=True, text=True, timeout=120)
    assert walked.returncode in (0, 1), walked.stderr[-2000:]  # walked (0) or fell (1): a judged outcome
    assert json.loads(walked.stdout)["policy"].startswith("learned/best.pt")


@pytest.mark.slow
def test_sb3_trains_the_shipped_configuration_checkpoints_and_resumes(tmp_path):
    """The shipped policy's episodes (memory inputs, a residual on classic + the speed
    integral) under SB3's PPO: the actor starts at the zero residual, its checkpoint runs as a
    learned policy with those inputs and outputs, and a run stopped at 256 env steps resumes
    from its checkpoint to 512 in all."""
    out = tmp_path / "sb3"
    common = ["scripts/train_sb3.py", "--config", "config/train/sb3_shipped_ppo.yaml", "--out", str(out),
              "--envs", "1", "--n-steps", "128", "--batch-size", "64", "--max-steps", "50", "--log-every", "128",
              "--eval-every", "0", "--checkpoint-every", "128", "--workers", "1", "--no-progress"]
    first = subprocess.run([sys.executable, *common, "--timesteps", "256"], cwd=ROOT, capture_output=True, text=True,
                           timeout=600)
    assert first.returncode == 0, first.stderr[-3000:]
    assert (out / "sb3_checkpoint.zip").is_file()
    again = subprocess.run([sys.executable, *common, "--timesteps", "512"], cwd=ROOT, capture_output=True, text=True,
                           timeout=600)
    assert again.returncode == 2 and "--resume" in again.stderr  # a used --out needs --resume
    resumed = subprocess.run([sys.executable, *common, "--timesteps", "512", "--resume"], cwd=ROOT,
                             capture_output=True, text=True, timeout=600)
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert json.loads(resumed.stdout.strip().splitlines()[-1])["info"]["env_steps"] == 512
    with (out / "log.csv").open() as f:
        assert [int(r["env_steps"]) for r in csv.DictReader(f)] == [128, 256, 384, 512]  # one log, continued
    policy = make_policy("learned", policy_file=out / "policy.pt")
    info = policy.checkpoint.info
    assert (info["features"], info["action"], info["integral_gain"]) == ("memory", "residual", 0.2)
    assert policy.residual is not None and policy.memory is not None and policy.forward.inputs == 25
    from rabbit_policy.experiment.loop import walk
    from rabbit_policy.experiment.scenario import Scenario

    assert not walk(policy, Scenario.constant(1.0), 3.0).failed


def test_the_sb3_actor_of_a_residual_starts_at_the_zero_residual():
    from stable_baselines3.common.env_util import make_vec_env

    from rabbit_policy.runtime.actions import policy_bounds

    config = SB3Config(envs=1, max_steps=5, decision_period=20, distribution="paper", features="memory",
                       action="residual", integral_gain=0.2)
    env = make_vec_env(lambda: gym.make("RabbitHZD-v0", **config.env_kwargs()), n_envs=1, seed=0)
    model = build_model(config, env)
    bounds = policy_bounds("residual", GaitLibrary.load())
    assert warm_start_actor(model, config, bounds.low, bounds.high) is None
    net = export_actor(model, "ppo", bounds.low, bounds.high, config.policy_info()).network()
    obs = np.random.default_rng(0).uniform(-1.0, 1.0, (20, 25)).astype(np.float32)
    with torch.no_grad():
        assert np.array_equal(net(torch.as_tensor(obs)).numpy(), np.zeros((20, 21), np.float32))
    env.close()
