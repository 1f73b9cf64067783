"""Proximal Policy Optimisation for the HZD-RL policy, after CleanRL's
``ppo_continuous_action.py``, readable top to bottom.

* Actor: the shipped policy network itself (:class:`HZDPolicyNet`, 633 parameters) gives
  the mean action inside the bounds; exploration is a diagonal Gaussian around it whose
  standard deviation is ``exp(log_std)`` times the action range (one learned log-std per
  action dimension, in normalised units). The deterministic policy used after training is
  the mean, so a PPO checkpoint is the same file as an ES one.
* Critic: a separate 3 -> 64 -> 64 -> 1 tanh network on the same normalised inputs; with
  ``privileged_critic`` it also sees the env's ``info["privileged"]`` (the body state, the push
  acting and to come, the model and the delay: :data:`~rabbit_policy.learning.env.PRIVILEGED_STATE`),
  every input normalised online by running means and variances (ARS's state normalisation, for
  the critic only: the actor's inputs are the policy node's). Asymmetric actor-critic (Li et al.,
  IJRR 2024): a value that knows the push can tell a recovery from a lucky draw.
* ``normalize_rewards``: rewards divided by a running standard deviation of the discounted
  return (Gymnasium's ``NormalizeReward``), so the fall penalty and the tracking terms reach
  the critic at unit scale; ``separate_clip``: the actor's and the critic's gradients clipped
  each to ``max_grad_norm`` (one shared clip lets the critic's large early gradients shrink
  the actor's step to nothing). A horizon that reaches a failure 1-2 s after a push at 20 ms
  per step: ``gamma`` 0.995, ``gae_lambda`` 0.98 (the recovery preset's PPO configuration).
* One iteration: ``steps`` transitions from each of ``envs`` environments (a Gymnasium
  ``AsyncVectorEnv``, one process per environment, or one Ray actor per environment on the
  Ray backend: :mod:`rabbit_policy.learning.vector`; same-step autoreset); generalised
  advantage estimation (gamma, lambda); a truncated episode is bootstrapped with the
  critic's value of its final observation (a time limit is not a terminal state);
  ``epochs`` passes of minibatch updates of the clipped surrogate objective + value loss,
  advantages normalised per minibatch, gradients clipped; the epochs stop early once the
  approximate KL divergence from the rollout policy exceeds ``target_kl`` (as CleanRL's
  option).

Deterministic for a given seed and number of environments: every environment is seeded
from the seed, sampling uses a seeded torch generator, and the update is single-threaded.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from multiprocessing import parent_process

import numpy as np
import torch
from torch import nn

from rabbit_msgs_py.cli import option
from rabbit_policy.learning.env import PRIVILEGED_STATE, EpisodeConfig, RabbitHZDEnv
from rabbit_policy.learning.spec_env import make_env
from rabbit_policy.runtime.actions import policy_bounds
from rabbit_policy.learning.vector import make_vector_env
from rabbit_policy.parallel import Backend, ignore_interrupts
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.network import HZDPolicyNet


@dataclass(frozen=True)
class PPOConfig(EpisodeConfig):
    """PPO hyper-parameters (CleanRL's names), one ``scripts/train.py`` option each."""

    envs: int = option(4, "parallel environments")
    steps: int = option(128, "steps per environment per iteration (the rollout is envs x steps)")
    epochs: int = option(10, "optimisation epochs per iteration")
    minibatches: int = option(4, "minibatches per epoch")
    lr: float = option(1e-4, "Adam step size", flag="--ppo-lr")
    gamma: float = option(0.99, "discount (the paper: 0.99)")
    gae_lambda: float = option(0.95, "GAE lambda")
    clip: float = option(0.2, "PPO's ratio clip")
    value_coef: float = option(0.5, "value-loss weight")
    max_grad_norm: float = option(0.5, "gradient-norm clip")
    target_kl: float = option(0.02, "stop an iteration's epochs once the approximate KL passes it (0: never)")
    init_log_std: float = option(-3.5, "initial log std of the Gaussian policy, normalised action units")
    privileged_critic: bool = option(False, "the critic also sees the env's privileged state (body, push, model; "
                                            "info['privileged']), its inputs normalised online")
    normalize_rewards: bool = option(False, "divide rewards by a running std of the discounted return")
    separate_clip: bool = option(False, "clip the actor's and the critic's gradient norms separately")

    def __post_init__(self) -> None:
        super().__post_init__()
        if min(self.envs, self.steps, self.epochs, self.minibatches) < 1:
            raise ValueError("envs, steps, epochs and minibatches must be >= 1")
        if self.envs * self.steps < self.minibatches:
            raise ValueError("envs x steps must be at least minibatches")

    def to_dict(self) -> dict:
        return asdict(self)


class RunningMoments(nn.Module):
    """Running mean and variance of a vector (Chan's parallel update), as buffers."""

    def __init__(self, size: int) -> None:
        super().__init__()
        self.register_buffer("mean", torch.zeros(size, dtype=torch.float64))
        self.register_buffer("var", torch.ones(size, dtype=torch.float64))
        self.register_buffer("count", torch.tensor(1e-4, dtype=torch.float64))

    def update(self, batch: torch.Tensor) -> None:
        """Fold the rows of ``batch`` in."""
        batch = batch.to(torch.float64).reshape(-1, self.mean.numel())
        n = batch.shape[0]
        mean, var = batch.mean(0), batch.var(0, unbiased=False)
        total = self.count + n
        delta = mean - self.mean
        self.mean += delta * n / total
        self.var = (self.var * self.count + var * n + delta ** 2 * self.count * n / total) / total
        self.count = total

    def normalise(self, x: torch.Tensor) -> torch.Tensor:
        """``x`` centred and scaled, clipped to +-10."""
        return ((x - self.mean.float()) / torch.sqrt(self.var.float() + 1e-8)).clamp(-10.0, 10.0)


class Critic(nn.Module):
    """State value from the policy's inputs (m/s), normalised like the actor's; with
    ``privileged`` > 0 also from that many privileged entries, every input then normalised by
    running moments (:meth:`observe` folds a rollout's inputs in)."""

    def __init__(self, actor: HZDPolicyNet, hidden: int = 64, privileged: int = 0) -> None:
        super().__init__()
        self.register_buffer("offset", actor.offset.clone())
        self.register_buffer("scale", actor.scale.clone())
        size = actor.offset.numel() + privileged
        self.moments = RunningMoments(size) if privileged else None
        self.body = nn.Sequential(nn.Linear(size, hidden), nn.Tanh(), nn.Linear(hidden, hidden), nn.Tanh(),
                                  nn.Linear(hidden, 1))

    def observe(self, inputs: torch.Tensor) -> None:
        """Fold a rollout's critic inputs into the running moments (privileged critic only)."""
        if self.moments is not None:
            self.moments.update(inputs)

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        if self.moments is not None:
            return self.body(self.moments.normalise(inputs)).squeeze(-1)
        return self.body((inputs - self.offset) / self.scale).squeeze(-1)


class ReturnScale:
    """Gymnasium's ``NormalizeReward``: per environment the discounted return so far, its
    running variance over all environments; :meth:`__call__` divides a step's rewards by that
    standard deviation."""

    def __init__(self, envs: int, gamma: float) -> None:
        self.gamma = gamma
        self.returns = np.zeros(envs)
        self.moments = RunningMoments(1)

    def __call__(self, reward: np.ndarray, done: np.ndarray) -> np.ndarray:
        self.returns = self.returns * self.gamma + reward
        self.moments.update(torch.as_tensor(self.returns).reshape(-1, 1))
        self.returns[done] = 0.0
        return reward / float(torch.sqrt(self.moments.var[0] + 1e-8))

    def state_dict(self) -> dict:
        return {"returns": self.returns.copy(), "moments": self.moments.state_dict()}

    def load_state_dict(self, state: dict) -> None:
        self.returns = np.asarray(state["returns"], dtype=float).copy()
        self.moments.load_state_dict(state["moments"])


class GaussianPolicy(nn.Module):
    """The actor network plus a learned per-dimension log standard deviation."""

    def __init__(self, actor: HZDPolicyNet, init_log_std: float) -> None:
        super().__init__()
        self.actor = actor
        self.log_std = nn.Parameter(torch.full((actor.low.numel(),), float(init_log_std)))

    def distribution(self, obs: torch.Tensor) -> torch.distributions.Normal:
        std = torch.exp(self.log_std) * (self.actor.high - self.actor.low)
        return torch.distributions.Normal(self.actor(obs), std)


def _tracking_errors(info: dict, ended: np.ndarray) -> list[float]:
    """|mean hip speed - v_d| (m/s) of this step in every environment; an environment that
    ended reports it in ``final_info`` (same-step autoreset)."""
    final = info.get("final_info", {})
    errors = []
    for i, done in enumerate(ended):
        source = final if done else info
        errors.append(abs(float(source["mean_speed"][i]) - float(source["desired_speed"][i])))
    return errors


def _make_env(kwargs: dict):
    """A factory of the env with ``kwargs`` (:meth:`EpisodeConfig.env_kwargs`)."""
    def make() -> RabbitHZDEnv:
        if parent_process() is not None:  # a worker; AsyncVectorEnv also builds one env in the parent
            ignore_interrupts()
        return make_env(kwargs)

    return make


class PPOTrainer:
    """Stateful PPO over ``envs`` parallel environments (forked processes, or Ray actors on
    a Ray ``backend``: the same numbers either way); :meth:`step` is one iteration."""

    def __init__(self, net: HZDPolicyNet, config: PPOConfig, backend: Backend | None = None) -> None:
        torch.set_num_threads(1)
        self.config = config
        self.net = net
        self.policy = GaussianPolicy(net, config.init_log_std)
        self.bounds = policy_bounds(config.action, GaitLibrary.load())  # the env's: its actions are normalised
        torch.manual_seed(config.seed)
        self.critic = Critic(net, privileged=len(PRIVILEGED_STATE) if config.privileged_critic else 0)
        self.optimiser = torch.optim.Adam(list(self.policy.parameters()) + list(self.critic.parameters()),
                                          lr=config.lr, eps=1e-5)
        self.reward_scale = ReturnScale(config.envs, config.gamma) if config.normalize_rewards else None
        self.generator = torch.Generator().manual_seed(config.seed)
        self.rng = np.random.default_rng(config.seed)
        factory = _make_env(config.env_kwargs())
        self.envs = make_vector_env([factory] * config.envs, backend)
        self.iteration = 0
        self.env_steps = 0
        self._obs: np.ndarray | None = None
        self._privileged: np.ndarray | None = None  # info["privileged"] of self._obs
        self._episode_return = np.zeros(config.envs)
        self._episode_length = np.zeros(config.envs, dtype=int)

    def close(self, terminate: bool = False) -> None:
        """Stop the environment processes (``terminate``: at once; after Ctrl-C)."""
        self.envs.close(terminate=terminate)

    # ------------------------------------------------------------------ state
    def state_dict(self) -> dict:
        return {"policy": self.policy.state_dict(), "critic": self.critic.state_dict(),
                "optimiser": self.optimiser.state_dict(), "generator": self.generator.get_state(),
                "rng": self.rng.bit_generator.state, "iteration": self.iteration, "env_steps": self.env_steps,
                **({"reward_scale": self.reward_scale.state_dict()} if self.reward_scale is not None else {})}

    def load_state_dict(self, state: dict) -> None:
        """Resume: networks, optimiser and random streams; the environments start fresh
        episodes (seeded from the seed and the iteration)."""
        self.policy.load_state_dict(state["policy"])
        self.critic.load_state_dict(state["critic"])
        self.optimiser.load_state_dict(state["optimiser"])
        self.generator.set_state(state["generator"])
        self.rng.bit_generator.state = state["rng"]
        self.iteration, self.env_steps = state["iteration"], state["env_steps"]
        if self.reward_scale is not None:
            self.reward_scale.load_state_dict(state["reward_scale"])
        self._obs = None

    def _critic_inputs(self, obs: np.ndarray, privileged: np.ndarray | None) -> torch.Tensor:
        """What the critic sees of an observation: it, and with a privileged critic the
        env's privileged state beside it."""
        inputs = np.asarray(obs, dtype=np.float32)
        if self.config.privileged_critic:
            inputs = np.concatenate([inputs, np.asarray(privileged, dtype=np.float32)], axis=-1)
        return torch.as_tensor(inputs, dtype=torch.float32)

    # --------------------------------------------------------------- rollout
    def _collect(self) -> dict[str, torch.Tensor | list]:
        cfg = self.config
        if self._obs is None:
            seed = int(self.rng.integers(0, 2**31 - 1))
            self._obs, info = self.envs.reset(seed=seed)
            self._privileged = info.get("privileged")
            self._episode_return[:] = 0.0
            self._episode_length[:] = 0
        shape = (cfg.steps, cfg.envs)
        obs_buf = torch.zeros(shape + (self.net.offset.numel(),))
        critic_buf = torch.zeros(shape + (self.critic.body[0].in_features,))
        act_buf = torch.zeros(shape + (self.net.low.numel(),))
        logp_buf, rew_buf, done_buf, val_buf = (torch.zeros(shape) for _ in range(4))
        finished: list[tuple[float, int, bool]] = []
        errors: list[float] = []
        for t in range(cfg.steps):
            obs = torch.as_tensor(self._obs, dtype=torch.float32)
            critic_inputs = self._critic_inputs(self._obs, self._privileged)
            with torch.no_grad():
                dist = self.policy.distribution(obs)
                action = dist.mean + dist.stddev * torch.randn(dist.mean.shape, generator=self.generator)
                logp = dist.log_prob(action).sum(-1)
                value = self.critic(critic_inputs)
            next_obs, reward, terminated, truncated, info = self.envs.step(self.bounds.to_normalised(action.numpy()))
            reward = np.asarray(reward, dtype=float).copy()
            self._episode_return += reward  # the episode statistics: unscaled
            self._episode_length += 1
            if self.reward_scale is not None:
                reward = self.reward_scale(reward, terminated | truncated)
            errors.extend(_tracking_errors(info, terminated | truncated))
            for i in np.flatnonzero(truncated & ~terminated):  # bootstrap through the time limit
                final_privileged = info["final_info"]["privileged"][i] if cfg.privileged_critic else None
                final = self._critic_inputs(info["final_obs"][i], final_privileged)
                with torch.no_grad():
                    reward[i] += cfg.gamma * float(self.critic(final))
            for i in np.flatnonzero(terminated | truncated):
                finished.append((float(self._episode_return[i]), int(self._episode_length[i]), bool(terminated[i])))
                self._episode_return[i], self._episode_length[i] = 0.0, 0
            obs_buf[t], act_buf[t], logp_buf[t], val_buf[t] = obs, action, logp, value
            critic_buf[t] = critic_inputs
            rew_buf[t] = torch.as_tensor(reward, dtype=torch.float32)
            done_buf[t] = torch.as_tensor(terminated | truncated, dtype=torch.float32)
            self._obs, self._privileged = next_obs, info.get("privileged")
        self.env_steps += cfg.steps * cfg.envs
        with torch.no_grad():
            next_value = self.critic(self._critic_inputs(self._obs, self._privileged))
        advantages = torch.zeros(shape)
        last = torch.zeros(cfg.envs)
        for t in reversed(range(cfg.steps)):
            following = next_value if t == cfg.steps - 1 else val_buf[t + 1]
            not_done = 1.0 - done_buf[t]
            delta = rew_buf[t] + cfg.gamma * following * not_done - val_buf[t]
            last = delta + cfg.gamma * cfg.gae_lambda * not_done * last
            advantages[t] = last
        self.critic.observe(critic_buf)  # the update (and the next rollout) sees the moments with this rollout in
        return {"obs": obs_buf.reshape(-1, obs_buf.shape[-1]), "critic": critic_buf.reshape(-1, critic_buf.shape[-1]),
                "actions": act_buf.reshape(-1, act_buf.shape[-1]),
                "logp": logp_buf.reshape(-1), "advantages": advantages.reshape(-1),
                "returns": (advantages + val_buf).reshape(-1), "finished": finished, "errors": errors}

    # ---------------------------------------------------------------- update
    def step(self) -> dict[str, float]:
        """One iteration (rollout + update); returns statistics of the finished episodes
        (mean return, fall fraction), the mean |v̄ - v_d| per step, losses, env steps."""
        cfg = self.config
        batch = self._collect()
        n = batch["obs"].shape[0]
        size = n // cfg.minibatches
        clip_fractions, policy_losses, value_losses = [], [], []
        approx_kl = 0.0
        for _ in range(cfg.epochs):
            order = torch.randperm(n, generator=self.generator)
            for start in range(0, n, size):
                idx = order[start:start + size]
                dist = self.policy.distribution(batch["obs"][idx])
                logp = dist.log_prob(batch["actions"][idx]).sum(-1)
                log_ratio = logp - batch["logp"][idx]
                ratio = torch.exp(log_ratio)
                with torch.no_grad():
                    approx_kl = ((ratio - 1) - log_ratio).mean().item()  # CleanRL's k3 estimator
                adv = batch["advantages"][idx]
                adv = (adv - adv.mean()) / (adv.std() + 1e-8)
                policy_loss = torch.max(-adv * ratio, -adv * ratio.clamp(1 - cfg.clip, 1 + cfg.clip)).mean()
                value_loss = 0.5 * ((self.critic(batch["critic"][idx]) - batch["returns"][idx]) ** 2).mean()
                loss = policy_loss + cfg.value_coef * value_loss
                self.optimiser.zero_grad()
                loss.backward()
                if cfg.separate_clip:
                    nn.utils.clip_grad_norm_(self.policy.parameters(), cfg.max_grad_norm)
                    nn.utils.clip_grad_norm_(self.critic.parameters(), cfg.max_grad_norm)
                else:
                    nn.utils.clip_grad_norm_(list(self.policy.parameters()) + list(self.critic.parameters()),
                                             cfg.max_grad_norm)
                self.optimiser.step()
                clip_fractions.append(((ratio - 1).abs() > cfg.clip).float().mean().item())
                policy_losses.append(policy_loss.item())
                value_losses.append(value_loss.item())
            if cfg.target_kl and approx_kl > cfg.target_kl:
                break
        self.iteration += 1
        finished = batch["finished"]
        return {
            "iteration": self.iteration,
            "env_steps": self.env_steps,
            "episodes": len(finished),
            "episode_return": float(np.mean([r for r, _, _ in finished])) if finished else float("nan"),
            "fall_fraction": float(np.mean([f for _, _, f in finished])) if finished else float("nan"),
            "mean_abs_error": float(np.mean(batch["errors"])),
            "policy_loss": float(np.mean(policy_losses)),
            "value_loss": float(np.mean(value_losses)),
            "clip_fraction": float(np.mean(clip_fractions)),
            "approx_kl": approx_kl,
            "log_std": self.policy.log_std.detach().mean().item(),
        }
