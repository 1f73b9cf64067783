"""A stable-baselines3 baseline on ``RabbitHZD-v0`` (``scripts/train_sb3.py``): SB3's PPO or
SAC on the same environment, judged by the same acceptance, with outputs a ``train.py`` run
has (``log.csv``, ``eval.csv``, ``tb/`` under the same tags, ``policy.pt``, ``best.pt``,
``summary.json``), so ``plot_training.py`` and TensorBoard overlay it with our ES and PPO.

* The actor is our network's shape: 3 -> 12 -> 12 -> 12 -> 21, tanh (``net_arch`` pi =
  [12, 12, 12]), on the raw observation (m/s); the critic(s) 64 x 64. PPO's deterministic
  action is the Gaussian mean clipped to [-1, 1]; SAC's the tanh-squashed mean.
* :func:`export_actor` copies the actor into an :class:`HZDPolicyNet` (``output`` "clip" or
  "tanh"), a :class:`PolicyCheckpoint` that ``policy_node`` and ``walk.py --policy-file`` run
  without SB3 (tested: the same actions as SB3's ``predict(deterministic=True)``).
* ``warm_start`` "feedback" fits that actor to the classic library first (the warm start of
  our runs, ``rabbit_policy.learning.warm_start``), so SB3 starts where ES and PPO start;
  "none" is SB3 from scratch.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from rabbit_msgs_py import strict_json
from rabbit_msgs_py.cli import option
from rabbit_policy.learning.env import EpisodeConfig
from rabbit_policy.runtime.network import HZDPolicyNet, PolicyCheckpoint

ALGORITHMS = ("ppo", "sac")
OUTPUT = {"ppo": "clip", "sac": "tanh"}


@dataclass(frozen=True)
class SB3Config(EpisodeConfig):
    """One SB3 run, one ``scripts/train_sb3.py`` option each (SB3's names where it has them)."""

    algo: str = option("ppo", "the SB3 algorithm", choices=ALGORITHMS)
    timesteps: int = option(100_000, "env steps in all")
    envs: int = option(2, "parallel environments (subprocesses; SAC: 1)")
    n_steps: int = option(512, "PPO: steps per environment per rollout")
    batch_size: int = option(64, "minibatch size (PPO) / batch size (SAC)")
    learning_rate: float = option(3e-4, "Adam step size")
    gamma: float = option(0.99, "discount (the paper: 0.99)")
    log_std_init: float = option(-2.0, "initial log std of the Gaussian policy, normalised action units")
    warm_start: str = option("feedback", "fit the actor to the classic library first (none: SB3 from scratch)",
                             choices=("feedback", "none"))
    log_every: int = option(2048, "env steps between log.csv rows")
    eval_every: int = option(20_000, "env steps between acceptance evaluations (and at the start and end; 0: "
                                     "at the end only)")
    workers: int = option(2, "processes (or Ray CPUs) for the acceptance evaluations")

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.algo not in ALGORITHMS:
            raise ValueError(f"algo must be one of {ALGORITHMS}, got {self.algo!r}")
        if min(self.timesteps, self.envs, self.n_steps, self.batch_size, self.log_every, self.workers) < 1:
            raise ValueError("timesteps, envs, n_steps, batch_size, log_every and workers must be >= 1")
        if self.eval_every < 0:
            raise ValueError("eval_every must be >= 0")
        if self.features != "paper":
            raise ValueError("the SB3 baseline takes the paper's inputs only (features paper)")
        if self.action != "direct":
            raise ValueError("the SB3 baseline outputs the gait itself (action direct)")
        if not (self.learning_rate > 0.0 and 0.0 < self.gamma <= 1.0):
            raise ValueError("learning_rate must be > 0 and gamma in (0, 1]")

    def env_kwargs(self) -> dict:
        """``gymnasium.make("RabbitHZD-v0", **kwargs)`` for this run's episodes."""
        return {"max_steps": self.max_steps, "max_episode_steps": self.max_steps,
                "decision_period": self.decision_period, "distribution": self.distribution,
                "fall_penalty": self.fall_penalty}


def actor_layers(model) -> list[torch.nn.Linear]:
    """The four linear layers of an SB3 PPO or SAC actor, input to output."""
    from stable_baselines3 import SAC

    if isinstance(model, SAC):
        hidden, last = model.actor.latent_pi, model.actor.mu
    else:
        hidden, last = model.policy.mlp_extractor.policy_net, model.policy.action_net
    return [m for m in hidden if isinstance(m, torch.nn.Linear)] + [last]


def export_actor(model, algo: str, low: np.ndarray, high: np.ndarray, info: dict) -> PolicyCheckpoint:
    """SB3's deterministic actor as a policy file our runtime runs (see the module docstring)."""
    net = HZDPolicyNet(low, high, speed_centre=0.0, input_scale=1.0, output=OUTPUT[algo])
    linears = [m for m in net.body if isinstance(m, torch.nn.Linear)]
    with torch.no_grad():
        for ours, theirs in zip(linears, actor_layers(model), strict=True):
            ours.weight.copy_(theirs.weight)
            ours.bias.copy_(theirs.bias)
    return PolicyCheckpoint({k: v.clone() for k, v in net.state_dict().items()}, low, high,
                            {**info, "output": OUTPUT[algo]})


def warm_start_actor(model, algo: str, low: np.ndarray, high: np.ndarray, seed: int) -> float:
    """Fit the SB3 actor to the classic library ("feedback", as our runs); returns the fit's
    mean squared error in normalised action units."""
    from rabbit_policy.learning.warm_start import WARM_STARTS, warm_start
    from rabbit_policy.runtime.gait_library import GaitLibrary

    torch.manual_seed(seed)
    net = HZDPolicyNet(low, high, speed_centre=0.0, input_scale=1.0, output=OUTPUT[algo])
    mse = warm_start(net, GaitLibrary.load(), seed=seed, config=WARM_STARTS["feedback"])
    linears = [m for m in net.body if isinstance(m, torch.nn.Linear)]
    with torch.no_grad():
        for ours, theirs in zip(linears, actor_layers(model), strict=True):
            theirs.weight.copy_(ours.weight)
            theirs.bias.copy_(ours.bias)
    return mse


def build_model(config: SB3Config, env):
    """The SB3 model for ``config`` on the vectorised ``env``."""
    from stable_baselines3 import PPO, SAC

    common = {"learning_rate": config.learning_rate, "gamma": config.gamma, "seed": config.seed, "verbose": 0,
              "device": "cpu"}
    if config.algo == "ppo":
        kwargs = {"net_arch": {"pi": [12, 12, 12], "vf": [64, 64]}, "activation_fn": torch.nn.Tanh,
                  "log_std_init": config.log_std_init}
        return PPO("MlpPolicy", env, n_steps=config.n_steps, batch_size=config.batch_size, policy_kwargs=kwargs,
                   **common)
    kwargs = {"net_arch": {"pi": [12, 12, 12], "qf": [64, 64]}, "activation_fn": torch.nn.Tanh,
              "log_std_init": config.log_std_init}
    return SAC("MlpPolicy", env, batch_size=config.batch_size, policy_kwargs=kwargs, **common)


def train_sb3(config: SB3Config, out: Path, progress: bool = True, backend_config=None) -> dict:
    """Train as configured into ``out`` (new or empty), the acceptance evaluations on
    ``backend_config`` (a :class:`~rabbit_policy.parallel.BackendConfig`; None: a local pool
    of ``config.workers``); returns the summary (also ``summary.json``)."""
    import gymnasium as gym
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv
    from tqdm import tqdm

    import rabbit_policy  # noqa: F401  (registers RabbitHZD-v0)
    from rabbit_policy.evaluation.acceptance import acceptance, acceptance_rank
    from rabbit_policy.learning.env import ActionBounds
    from rabbit_policy.learning.scalars import TrainingScalars
    from rabbit_policy.learning.training import append_csv, evaluation_row
    from rabbit_policy.parallel import BackendConfig, make_backend
    from rabbit_policy.runtime.gait_library import GaitLibrary
    from rabbit_policy.runtime.policies import NetworkPolicy

    torch.set_num_threads(1)
    out.mkdir(parents=True, exist_ok=True)
    bounds = ActionBounds.from_library(GaitLibrary.load())
    envs = 1 if config.algo == "sac" else config.envs
    env = make_vec_env(lambda: gym.make("RabbitHZD-v0", **config.env_kwargs()), n_envs=envs, seed=config.seed,
                       vec_env_cls=SubprocVecEnv if envs > 1 else DummyVecEnv,
                       vec_env_kwargs={"start_method": "fork"} if envs > 1 else None)
    model = build_model(config, env)
    mse = warm_start_actor(model, config.algo, bounds.low, bounds.high, config.seed) \
        if config.warm_start == "feedback" else None
    backend = make_backend(backend_config or BackendConfig("local", config.workers))
    scalars = TrainingScalars(out / "tb", f"sb3_{config.algo}")
    start = time.perf_counter()
    state = {"best": None, "iteration": 0}

    def info() -> dict:
        return {"algorithm": f"sb3_{config.algo}", "seed": config.seed, "config": asdict(config),
                "warm_start": config.warm_start, "warm_start_mse": mse, "env_steps": int(model.num_timesteps),
                "wall_s": round(time.perf_counter() - start, 1)}

    def evaluate() -> None:
        checkpoint = export_actor(model, config.algo, bounds.low, bounds.high, info())
        checkpoint.save(out / "policy.pt")
        result = acceptance(NetworkPolicy(checkpoint.network(), decision_period=config.decision_period),
                            map_fn=backend.map)
        row = evaluation_row(state["iteration"], time.perf_counter() - start, int(model.num_timesteps), result)
        append_csv(out / "eval.csv", row)
        scalars.evaluation(row)
        rank = list(acceptance_rank(result))
        if model.num_timesteps > 0 and (state["best"] is None or rank < state["best"]["rank"]):
            state["best"] = {**row, "rank": rank}
            PolicyCheckpoint(checkpoint.state_dict, bounds.low, bounds.high,
                             {**checkpoint.info, "acceptance": result}).save(out / "best.pt")

    class Logger(BaseCallback):
        """log.csv rows, TensorBoard scalars and evaluations every so many env steps."""

        def _on_training_start(self) -> None:
            self.returns, self.falls, self.errors = [], [], []
            self.next_log, self.next_eval = config.log_every, config.eval_every or config.timesteps + 1
            self.bar = tqdm(total=config.timesteps, unit="step", disable=not progress, dynamic_ncols=True)

        def _on_training_end(self) -> None:
            self.bar.close()

        def _on_step(self) -> bool:
            self.bar.update(self.num_timesteps - self.bar.n)
            for i, step_info in enumerate(self.locals["infos"]):
                self.errors.append(abs(step_info["mean_speed"] - step_info["desired_speed"]))
                if self.locals["dones"][i] and "episode" in step_info:  # Monitor's end-of-episode record
                    self.returns.append(step_info["episode"]["r"])
                    self.falls.append(bool(step_info["fell"] or step_info["stalled"]))
            if self.num_timesteps >= self.next_log:
                self.next_log += config.log_every
                state["iteration"] += 1
                row = {"wall_s": round(time.perf_counter() - start, 1), "iteration": state["iteration"],
                       "env_steps": int(self.num_timesteps), "episodes": len(self.returns),
                       "episode_return": float(np.mean(self.returns)) if self.returns else float("nan"),
                       "fall_fraction": float(np.mean(self.falls)) if self.falls else float("nan"),
                       "mean_abs_error": float(np.mean(self.errors)) if self.errors else float("nan")}
                append_csv(out / "log.csv", row)
                scalars.iteration(row, row["wall_s"])
                self.bar.set_postfix(ret=f"{row['episode_return']:.2f}", falls=f"{row['fall_fraction']:.2f}")
                self.returns, self.falls, self.errors = [], [], []
            if self.num_timesteps >= self.next_eval:
                self.next_eval += config.eval_every
                evaluate()
            return True

    try:
        if config.eval_every:
            evaluate()  # the starting point (the warm start, or SB3's initial actor)
        model.learn(total_timesteps=config.timesteps, callback=Logger())
        evaluate()
        model.save(out / "sb3_model.zip")
    finally:
        env.close()
        backend.close()
        scalars.close()
    best = state["best"]
    summary = {"info": info(), "best": None if best is None else {k: best[k] for k in ("env_steps", "failures",
                                                                                        "total_error")}}
    (out / "summary.json").write_text(strict_json.dumps(summary, indent=2) + "\n")
    return summary
