"""A stable-baselines3 baseline on ``RabbitHZD-v0`` (``scripts/train_sb3.py``): SB3's PPO or
SAC on the same environment, judged by the same acceptance, with outputs a ``train.py`` run
has (``log.csv``, ``eval.csv``, ``tb/`` under the same tags, ``policy.pt``, ``best.pt``,
``summary.json``), so ``plot_training.py`` and TensorBoard overlay it with our ES and PPO.

* The actor is our network's shape: inputs -> 12 -> 12 -> 12 -> 21, tanh (``net_arch`` pi =
  [12, 12, 12]), on the raw observation; the critic(s) 64 x 64. PPO's deterministic
  action is the Gaussian mean clipped to [-1, 1]; SAC's the tanh-squashed mean. Any
  configuration ``train.py`` trains: the paper's three inputs or the memory and body ones,
  the gait or a residual (on the library or on the recovery controller), so the shipped
  configuration (``config/train/sb3_shipped_ppo.yaml``) can be cross-checked; the checkpoint
  carries what ``checkpoint_policy`` needs to run it (features, memory, residual, base).
* :func:`export_actor` copies the actor into an :class:`HZDPolicyNet` (``output`` "clip" or
  "tanh"), a :class:`PolicyCheckpoint` that ``policy_node`` and ``walk.py --policy-file`` run
  without SB3 (tested: the same actions as SB3's ``predict(deterministic=True)``).
* ``warm_start`` "feedback" fits that actor to the classic library first (the warm start of
  our runs, ``rabbit_policy.learning.warm_start``), so SB3 starts where ES and PPO start (a
  residual: the actor's last layer at zero, the zero residual); "none" is SB3 from scratch.
* Every ``checkpoint_every`` env steps (and at the end and on Ctrl-C) ``sb3_checkpoint.zip``
  (SB3's save) and ``sb3_state.json``; ``--resume`` continues from them to ``timesteps`` in all.
"""

from __future__ import annotations

import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from rabbit_msgs_py import strict_json
from rabbit_msgs_py.cli import option, positive_int
import rabbit_policy  # noqa: F401  (registers RabbitHZD-v0 for gym.make)
from rabbit_policy.evaluation.acceptance import acceptance, acceptance_rank
from rabbit_policy.learning.env import EpisodeConfig
from rabbit_policy.learning.scalars import TrainingScalars
from rabbit_policy.learning.training import append_csv, evaluation_row
from rabbit_policy.learning.warm_start import WARM_STARTS, warm_start
from rabbit_policy.parallel import BackendConfig, make_backend
from rabbit_policy.runtime.actions import RESIDUAL_SCALE, policy_bounds
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.network import HZDPolicyNet, PolicyCheckpoint
from rabbit_policy.spec.make import checkpoint_policy

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
    workers: int = option(2, "processes (or Ray CPUs) for the acceptance evaluations", type=positive_int)
    checkpoint_every: int = option(20_000, "env steps between sb3_checkpoint.zip saves (and at the end and on "
                                           "Ctrl-C), what --resume continues from")

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.algo not in ALGORITHMS:
            raise ValueError(f"algo must be one of {ALGORITHMS}, got {self.algo!r}")
        if min(self.timesteps, self.envs, self.n_steps, self.batch_size, self.log_every, self.workers,
               self.checkpoint_every) < 1:
            raise ValueError("timesteps, envs, n_steps, batch_size, log_every, workers and checkpoint_every must be "
                             ">= 1")
        if self.eval_every < 0:
            raise ValueError("eval_every must be >= 0")
        if not (self.learning_rate > 0.0 and 0.0 < self.gamma <= 1.0):
            raise ValueError("learning_rate must be > 0 and gamma in (0, 1]")

    def env_kwargs(self) -> dict:
        """``gymnasium.make("RabbitHZD-v0", **kwargs)`` for this run's episodes (the TimeLimit's
        length the env's own)."""
        return {**super().env_kwargs(), "max_episode_steps": self.max_steps}

    def policy_info(self) -> dict:
        """What a checkpoint of this run says so that ``checkpoint_policy`` rebuilds its inputs and
        outputs (as ``train.py`` writes them)."""

        memory = self.memory_config(GaitLibrary.load().speed_range)
        return {"features": self.features, "action": self.action,
                **({"memory": memory.to_dict()} if memory is not None else {}),
                **({"residual_scale": list(RESIDUAL_SCALE), "integral_gain": self.integral_gain,
                    "residual_base": self.residual_base} if self.action == "residual" else {})}


def actor_layers(model) -> list[torch.nn.Linear]:
    """The four linear layers of an SB3 PPO or SAC actor, input to output."""
    from stable_baselines3 import SAC

    if isinstance(model, SAC):
        hidden, last = model.actor.latent_pi, model.actor.mu
    else:
        hidden, last = model.policy.mlp_extractor.policy_net, model.policy.action_net
    return [m for m in hidden if isinstance(m, torch.nn.Linear)] + [last]


def raw_input_net(low: np.ndarray, high: np.ndarray, output: str, inputs: int) -> HZDPolicyNet:
    """Our network on raw inputs (offset 0, scale 1: SB3's actor sees the observation as it is)."""
    net = HZDPolicyNet(low, high, output=output, inputs=inputs)
    with torch.no_grad():
        net.offset.zero_()
        net.scale.fill_(1.0)
    return net


def export_actor(model, algo: str, low: np.ndarray, high: np.ndarray, info: dict) -> PolicyCheckpoint:
    """SB3's deterministic actor as a policy file our runtime runs (see the module docstring)."""
    net = raw_input_net(low, high, OUTPUT[algo], actor_layers(model)[0].in_features)
    linears = [m for m in net.body if isinstance(m, torch.nn.Linear)]
    with torch.no_grad():
        for ours, theirs in zip(linears, actor_layers(model), strict=True):
            ours.weight.copy_(theirs.weight)
            ours.bias.copy_(theirs.bias)
    return PolicyCheckpoint({k: v.clone() for k, v in net.state_dict().items()}, low, high,
                            {**info, "output": OUTPUT[algo]})


def warm_start_actor(model, config: SB3Config, low: np.ndarray, high: np.ndarray) -> float | None:
    """Start the SB3 actor where our runs start: a residual at zero (its last layer zeroed:
    exactly the residual's base), the gait fitted to the classic library ("feedback", on the
    paper's three inputs, the others at zero weight); returns the fit's mean squared error in
    normalised action units (None for a residual)."""

    layers = actor_layers(model)
    if config.action == "residual":
        with torch.no_grad():
            layers[-1].weight.zero_()
            layers[-1].bias.zero_()
        return None
    torch.manual_seed(config.seed)
    net = raw_input_net(low, high, OUTPUT[config.algo], 3)
    mse = warm_start(net, GaitLibrary.load(), seed=config.seed, config=WARM_STARTS["feedback"])
    linears = [m for m in net.body if isinstance(m, torch.nn.Linear)]
    with torch.no_grad():
        for i, (ours, theirs) in enumerate(zip(linears, layers, strict=True)):
            if i == 0:  # the paper's three inputs; memory and body inputs at zero weight
                theirs.weight.zero_()
                theirs.weight[:, :ours.in_features].copy_(ours.weight)
            else:
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


CHECKPOINT, STATE = "sb3_checkpoint.zip", "sb3_state.json"


def training_envs(config: SB3Config):
    """The vectorised ``RabbitHZD-v0`` envs SB3 trains on: ``config.envs`` (one for SAC), in
    forked subprocesses when more than one, seeded from ``config.seed``."""
    import gymnasium as gym
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    envs = 1 if config.algo == "sac" else config.envs
    return make_vec_env(lambda: gym.make("RabbitHZD-v0", **config.env_kwargs()), n_envs=envs, seed=config.seed,
                        vec_env_cls=SubprocVecEnv if envs > 1 else DummyVecEnv,
                        vec_env_kwargs={"start_method": "fork"} if envs > 1 else None)


def rollout_row(iteration: int, env_steps: int, wall_s: float, returns: list[float], falls: list[bool],
                errors: list[float]) -> dict:
    """One ``log.csv`` row: the episodes ended since the last row (their mean return and fall
    fraction) and the mean |v - v_d| (m/s) of the env steps; NaN where there were none."""
    return {"wall_s": round(wall_s, 1), "iteration": iteration, "env_steps": env_steps, "episodes": len(returns),
            "episode_return": float(np.mean(returns)) if returns else float("nan"),
            "fall_fraction": float(np.mean(falls)) if falls else float("nan"),
            "mean_abs_error": float(np.mean(errors)) if errors else float("nan")}


def due(every: int, done: int) -> int:
    """The next multiple of ``every`` env steps after ``done``."""
    return (done // every + 1) * every


def progress_line(row: dict) -> str:
    """The console's line for a :func:`rollout_row` (one per iteration, on stderr)."""
    return (f"iteration {row['iteration']}: {row['env_steps']} env steps, {row['episodes']} episodes, "
            f"return {row['episode_return']:.2f}, falls {row['fall_fraction']:.2f}, |v - v_d| "
            f"{row['mean_abs_error']:.3f} m/s, {row['wall_s']:.0f} s")


def train_sb3(config: SB3Config, out: Path, progress: bool = True, backend_config=None, resume: bool = False) -> dict:
    """Train as configured into ``out`` (new or empty; with ``resume`` from its checkpoint, to
    ``config.timesteps`` in all), the acceptance evaluations on ``backend_config`` (a
    :class:`~rabbit_policy.parallel.BackendConfig`; None: a local pool of ``config.workers``);
    returns the summary (also ``summary.json``). Ctrl-C saves a checkpoint, then stops."""
    import json

    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm import tqdm

    torch.set_num_threads(1)
    out.mkdir(parents=True, exist_ok=True)
    bounds = policy_bounds(config.action, GaitLibrary.load())
    env = training_envs(config)
    state = {"best": None, "iteration": 0, "wall_s": 0.0, "warm_start_mse": None}
    if resume:
        model = {"ppo": PPO, "sac": SAC}[config.algo].load(out / CHECKPOINT, env=env, device="cpu")
        state.update(json.loads((out / STATE).read_text()))
    else:
        model = build_model(config, env)
        if config.warm_start == "feedback":
            state["warm_start_mse"] = warm_start_actor(model, config, bounds.low, bounds.high)
    backend = make_backend(backend_config or BackendConfig("local", config.workers))
    scalars = TrainingScalars(out / "tb", f"sb3_{config.algo}")
    start = time.perf_counter() - state["wall_s"]

    def info() -> dict:
        return {"algorithm": f"sb3_{config.algo}", "seed": config.seed, "config": asdict(config),
                "warm_start": config.warm_start, "warm_start_mse": state["warm_start_mse"],
                "env_steps": int(model.num_timesteps), "wall_s": round(time.perf_counter() - start, 1),
                **config.policy_info()}

    def save_checkpoint() -> None:
        model.save(out / CHECKPOINT)
        (out / STATE).write_text(strict_json.dumps({**state, "wall_s": time.perf_counter() - start}) + "\n")

    evaluated_at = [-1]  # env steps of the last evaluation: one eval.csv row per iteration

    def evaluate() -> None:
        if int(model.num_timesteps) == evaluated_at[0]:
            return  # the last in-loop evaluation was at these very steps
        evaluated_at[0] = int(model.num_timesteps)
        checkpoint = export_actor(model, config.algo, bounds.low, bounds.high, info())
        checkpoint.save(out / "policy.pt")
        result = acceptance(checkpoint_policy(out / "policy.pt"), map_fn=backend.map)
        row = evaluation_row(state["iteration"], time.perf_counter() - start, int(model.num_timesteps), result)
        append_csv(out / "eval.csv", row)
        scalars.evaluation(row)
        rank = list(acceptance_rank(result))
        if model.num_timesteps > 0 and (state["best"] is None or rank < state["best"]["rank"]):
            state["best"] = {**row, "rank": rank}
            PolicyCheckpoint(checkpoint.state_dict, bounds.low, bounds.high,
                             {**checkpoint.info, "acceptance": result}).save(out / "best.pt")

    class Logger(BaseCallback):
        """log.csv rows, TensorBoard scalars, evaluations and checkpoints every so many env steps."""

        def _on_training_start(self) -> None:
            done = int(self.num_timesteps)
            self.returns, self.falls, self.errors = [], [], []
            self.next_log = due(config.log_every, done)
            self.next_eval = due(config.eval_every, done) if config.eval_every else config.timesteps + 1
            self.next_checkpoint = due(config.checkpoint_every, done)
            self.bar = tqdm(total=config.timesteps, initial=done, unit="step", disable=not progress,
                            dynamic_ncols=True)

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
                row = rollout_row(state["iteration"], int(self.num_timesteps), time.perf_counter() - start,
                                  self.returns, self.falls, self.errors)
                append_csv(out / "log.csv", row)
                scalars.iteration(row, row["wall_s"])
                self.bar.set_postfix(ret=f"{row['episode_return']:.2f}", falls=f"{row['fall_fraction']:.2f}")
                tqdm.write(progress_line(row), file=sys.stderr)
                self.returns, self.falls, self.errors = [], [], []
            if self.num_timesteps >= self.next_eval:
                self.next_eval += config.eval_every
                evaluate()
            if self.num_timesteps >= self.next_checkpoint:
                self.next_checkpoint += config.checkpoint_every
                save_checkpoint()
            return True

    interrupted = False
    try:
        if config.eval_every and not resume:
            evaluate()  # the starting point (the warm start, or SB3's initial actor)
        remaining = config.timesteps - int(model.num_timesteps)
        if remaining > 0:
            try:
                model.learn(total_timesteps=remaining, callback=Logger(), reset_num_timesteps=not resume)
            except KeyboardInterrupt:
                interrupted = True
        if not interrupted:
            evaluate()
            model.save(out / "sb3_model.zip")
        save_checkpoint()
    finally:
        env.close()
        backend.close()
        scalars.close()
    best = state["best"]
    summary = {"info": info(), "interrupted": interrupted,
               "best": None if best is None else {k: best[k] for k in ("env_steps", "failures", "total_error")}}
    (out / "summary.json").write_text(strict_json.dumps(summary, indent=2) + "\n")
    return summary
