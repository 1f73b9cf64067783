"""Evolution Strategies for the HZD-RL policy (the paper's ES; modern practice after
OpenAI-ES and ARS), readable top to bottom.

Per generation, from the current parameters theta (flat vector of the network's 633):
1. draw ``pairs`` Gaussian directions eps_i and evaluate theta + sigma eps_i and
   theta - sigma eps_i (antithetic sampling) on the *same* episodes (common random
   numbers: every member sees the same v_d draws, ``episodes`` per evaluation, the
   commands stratified over 0.7-1.5 m/s, see :func:`stratified_episodes`);
2. replace the returns by centred ranks in [-0.5, 0.5] (rank normalisation: robust to
   the fall penalty's scale);
3. gradient estimate g = sum_i (rank+_i - rank-_i) eps_i / (2 pairs sigma), plus weight
   decay; Adam step on theta. With ``top`` = b > 0 (ARS V2-t) only the b pairs whose better
   member ranked highest enter the sum (divided by 2 b sigma). With ``optimizer: ars``
   (Mania, Guy, Recht 2018) instead theta += lr (sum_i (R+_i - R-_i) eps_i / (b std R) - decay
   theta): raw returns, the step scaled by the std of the 2b returns, no Adam (which turns a
   noise gradient into full steps: docs/learning.md).
With ``guard`` = n > 0 an update is a constrained step: the new parameters are rolled out on a
fixed set of n episodes each pushed forward (:func:`guard_episodes` of ``guard_set``, drawn
once from the seed) and taken only if they fall no more often there than the start did (plus
``guard_slack``); otherwise theta stays where it was and the next generation draws new
directions. Forward pushes are what every trained network traded for backward pushes and
changes (docs/learning.md): the guard keeps them out of the trade without a reward term.
Evaluations run on a :mod:`rabbit_policy.parallel` backend (a local process pool of
``workers``, or Ray); every evaluation is a pure function of (parameters, episodes) and
results come back in order, so a run is deterministic for a given seed whatever the
backend and the number of workers or nodes.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import torch

from rabbit_msgs_py.cli import option
from rabbit_policy.learning.env import EpisodeConfig, RabbitHZDEnv
from rabbit_policy.learning.spec_env import make_env
from rabbit_policy.parallel import Backend, LocalBackend, ignore_interrupts  # noqa: F401  (re-exported)
from rabbit_policy.evaluation.shipping import ScreenTrials
from rabbit_policy.runtime.fixed_order import vecmat
from rabbit_policy.runtime.network import HZDPolicyNet, NetworkForward, spec_network


OPTIMIZERS = ("adam", "ars")
GUARD_SETS = {"changes": "forward_guard", "screen": "screen_forward"}
"""The guard sets (:attr:`ESConfig.guard_set`) and the distribution each one's episodes draw from
(:data:`~rabbit_policy.learning.env.DISTRIBUTIONS`)."""
GUARD_STREAM = 1
"""The guard set is drawn from the generator seeded (seed, GUARD_STREAM): the same set for a
seed on every machine and after a resume, apart from the generations' draws."""


@dataclass(frozen=True)
class ESConfig(EpisodeConfig):
    """ES hyper-parameters, one ``scripts/train.py`` option each (defaults: the first shipped run's, config/train/first_shipped_es.yaml)."""

    pairs: int = option(8, "antithetic pairs per generation (the population is 2 x pairs)")
    sigma: float = option(0.005, "perturbation std, parameter units")
    lr: float = option(0.001, "Adam step size, parameter units")
    weight_decay: float = option(0.005, "L2 weight decay added to the gradient estimate")
    episodes: int = option(6, "episodes per population member (the same for every member)")
    top: int = option(0, "ARS's top-b: the update uses only the b pairs whose better member did best (0: all pairs)")
    optimizer: str = option("adam", "adam (centred ranks, an Adam step) or ars (ARS V2-t: the return differences "
                                    "over the returns' std, a plain step of lr; Mania et al. 2018)",
                            choices=OPTIMIZERS)
    guard: int = option(0, "episodes in the forward-push guard set: an update that falls there more often than the "
                           "start (+ guard_slack) is not taken (0: no guard)")
    guard_slack: int = option(0, "falls on the guard set an update may add to the start's, >= 0")
    guard_set: str = option("changes", "the guard's episodes: changes (changes' commands, 0.7-1.5 m/s, "
                                       "forward pushes 0.9-1.4x classic's margin) or screen (steady at the "
                                       "screen's push speeds in turn, forward pushes 1.0-1.3x)",
                            choices=tuple(GUARD_SETS))
    workers: int = option(1, "processes or Ray CPUs for the rollouts (the run's --workers)", cli=False)

    def __post_init__(self) -> None:
        super().__post_init__()
        if min(self.pairs, self.episodes, self.workers) < 1:
            raise ValueError("pairs, episodes and workers must be >= 1")
        if not 0 <= self.top <= self.pairs:
            raise ValueError(f"top must be in [0, pairs], got {self.top}")
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(f"optimizer must be one of {OPTIMIZERS}, got {self.optimizer!r}")
        if self.guard_set not in GUARD_SETS:
            raise ValueError(f"guard_set must be one of {tuple(GUARD_SETS)}, got {self.guard_set!r}")
        if min(self.guard, self.guard_slack) < 0:
            raise ValueError(f"guard and guard_slack must be >= 0, got {self.guard}, {self.guard_slack}")
        if not (self.sigma > 0.0 and self.lr > 0.0 and self.weight_decay >= 0.0):
            raise ValueError("sigma and lr must be > 0, weight_decay >= 0")

    def to_dict(self) -> dict:
        return asdict(self)


def get_flat(net: torch.nn.Module) -> np.ndarray:
    return torch.nn.utils.parameters_to_vector(net.parameters()).detach().double().numpy()


def set_flat(net: torch.nn.Module, theta: np.ndarray) -> None:
    torch.nn.utils.vector_to_parameters(torch.as_tensor(theta, dtype=torch.float32), net.parameters())


# ---------------------------------------------------------------- rollouts (per worker)
EnvKey = tuple[tuple[str, object], ...]
"""The env's arguments as sorted (name, value) pairs (:meth:`EpisodeConfig.env_kwargs`)."""
_WORKER: dict[EnvKey, tuple[RabbitHZDEnv, HZDPolicyNet]] = {}


def _worker_env(key: EnvKey) -> tuple[RabbitHZDEnv, HZDPolicyNet]:
    """This process's environment and network for ``key``, built on first use (each
    worker process, local or Ray, keeps its own)."""
    if key not in _WORKER:
        torch.set_num_threads(1)
        kwargs = dict(key)
        env = make_env(kwargs)
        if kwargs.get("spec"):  # the spec's network (its weights are set from theta before every use)
            net = spec_network(env.policy.forward)
        else:
            net = HZDPolicyNet(env.bounds.low, env.bounds.high, inputs=env.observation_space.shape[0],
                               output="tanh" if kwargs["action"] == "residual" else "sigmoid")
        _WORKER[key] = (env, net)
    return _WORKER[key]


@dataclass(frozen=True)
class Rollout:
    """One deterministic episode: undiscounted return, steps, summed |v̄ - v_d| (m/s), fell."""

    total: float
    steps: int
    abs_error: float
    fell: bool


Episode = tuple[int, float, float]  # (seed, first commanded speed, second commanded speed)


def stratified_episodes(rng: np.random.Generator, count: int, speed_range: tuple[float, float]) -> list[Episode]:
    """``count`` episodes whose first and second commands are stratified over the speed
    range (one draw in each of ``count`` equal sub-intervals, so each command is still
    uniform over the range). The first half of the episodes pairs the strata in reverse
    order (slowest start -> fastest end, ...): large speed changes, up and down, in every
    generation; the rest pair them at random. Less variance than independent draws, and the
    large changes — rare under independent draws, and where tracking is hardest — are
    always in the sample."""
    lo, hi = speed_range
    width = (hi - lo) / count
    first = lo + width * (np.arange(count) + rng.uniform(0.0, 1.0, count))
    order = np.arange(count)[::-1].copy()
    half = count // 2
    chosen = rng.choice(count, half, replace=False)  # which episodes get the reversed pairing
    rest = np.setdiff1d(np.arange(count), chosen)
    order[rest] = rng.permutation(order[rest])
    second = lo + width * (order + rng.uniform(0.0, 1.0, count))
    seeds = rng.integers(0, 2**31 - 1, count)
    return [(int(s), float(a), float(b)) for s, a, b in zip(seeds, first, second)]


def guard_episodes(rng: np.random.Generator, count: int, guard_set: str) -> list[Episode]:
    """The guard set's ``count`` episodes: ``changes``, :func:`stratified_episodes` over
    0.7-1.5 m/s; ``screen``, steady commands at the screen's push speeds
    (:class:`~rabbit_policy.evaluation.shipping.ScreenTrials`) in turn, each its own seed."""
    if count == 0:
        return []
    if guard_set == "changes":
        return stratified_episodes(rng, count, (0.7, 1.5))
    speeds = ScreenTrials().speeds
    seeds = rng.integers(0, 2**31 - 1, count)
    return [(int(s), speeds[i % len(speeds)], speeds[i % len(speeds)]) for i, s in enumerate(seeds)]


def episode_return(env: RabbitHZDEnv, net: HZDPolicyNet, episode: Episode) -> Rollout:
    """Deterministic policy rollout (the network's output is the action)."""
    seed, first, second = episode
    obs, _info = env.reset(seed=seed, options={"desired_speed": first, "next_speed": second})
    total, steps, abs_error = 0.0, 0, 0.0
    forward = NetworkForward.of(net)  # numpy per step, not torch
    while True:
        action = forward(obs)  # physical units
        obs, reward, terminated, truncated, info = env.step(env.bounds.to_normalised(action))
        total += reward
        steps += 1
        abs_error += abs(info["mean_speed"] - info["desired_speed"])
        if terminated or truncated:
            return Rollout(total, steps, abs_error, terminated)


def _evaluate(args: tuple[EnvKey, np.ndarray, list[Episode]]) -> list[Rollout]:
    key, theta, episodes = args
    env, net = _worker_env(key)
    set_flat(net, theta)
    return [episode_return(env, net, e) for e in episodes]


def centred_ranks(values: np.ndarray) -> np.ndarray:
    """Ranks mapped to [-0.5, 0.5] (ties broken by order, as in OpenAI-ES)."""
    ranks = np.empty(len(values))
    ranks[np.argsort(values, kind="stable")] = np.arange(len(values))
    return ranks / (len(values) - 1) - 0.5


@dataclass
class Adam:
    """Adam on a flat vector (ascent)."""

    lr: float
    beta1: float = 0.9
    beta2: float = 0.999
    eps: float = 1e-8
    t: int = 0
    m: np.ndarray | None = None
    v: np.ndarray | None = None

    def step(self, theta: np.ndarray, grad: np.ndarray) -> np.ndarray:
        if self.m is None:
            self.m, self.v = np.zeros_like(theta), np.zeros_like(theta)
        self.t += 1
        self.m = self.beta1 * self.m + (1 - self.beta1) * grad
        self.v = self.beta2 * self.v + (1 - self.beta2) * grad * grad
        m_hat = self.m / (1 - self.beta1 ** self.t)
        v_hat = self.v / (1 - self.beta2 ** self.t)
        return theta + self.lr * m_hat / (np.sqrt(v_hat) + self.eps)


class EvolutionStrategy:
    """Stateful ES optimiser over a policy network's parameters."""

    def __init__(self, net: HZDPolicyNet, config: ESConfig, backend: Backend | None = None) -> None:
        self.net = net
        self.config = config
        self.theta = get_flat(net)
        self.rng = np.random.default_rng(config.seed)
        self.adam = Adam(config.lr)
        self.generation = 0
        self.env_steps = 0
        self.env_key: EnvKey = tuple(sorted(config.env_kwargs().items()))
        self._own_backend = backend is None
        self.backend = backend if backend is not None else LocalBackend(config.workers)
        self.guard_key: EnvKey = tuple(sorted({**config.env_kwargs(),
                                               "distribution": GUARD_SETS[config.guard_set]}.items()))
        self.guard_episodes = guard_episodes(np.random.default_rng((config.seed, GUARD_STREAM)), config.guard,
                                             config.guard_set)
        self.guard_reference: int | None = None  # the start's falls on the guard set (measured at the first step)

    def close(self, terminate: bool = False) -> None:
        """Stop the workers if this optimiser started them (``terminate``: at once; after Ctrl-C)."""
        if self._own_backend:
            self.backend.close(terminate)

    def guard_falls(self, theta: np.ndarray) -> int:
        """Falls of ``theta`` on the guard set (its episodes split over the workers)."""
        chunks = [c for c in np.array_split(np.arange(len(self.guard_episodes)), self.config.workers) if len(c)]
        results = self.backend.map(_evaluate, [(self.guard_key, theta, [self.guard_episodes[i] for i in c])
                                               for c in chunks])
        self.env_steps += sum(r.steps for part in results for r in part)
        return sum(r.fell for part in results for r in part)

    def step(self) -> dict[str, float]:
        """One generation; returns statistics: mean/best population return; return, fall
        fraction and mean |v̄ - v_d| per step of the parameters the generation started
        from (same episodes); env steps so far; with a guard, its falls for the update and
        whether the update was taken."""
        cfg = self.config
        if cfg.guard and self.guard_reference is None:
            self.guard_reference = self.guard_falls(self.theta)
        before = self.theta
        seeds = stratified_episodes(self.rng, cfg.episodes, (0.7, 1.5))
        eps = self.rng.standard_normal((cfg.pairs, self.theta.size))
        candidates = [self.theta + cfg.sigma * e for e in eps] + [self.theta - cfg.sigma * e for e in eps]
        results = self.backend.map(_evaluate, [(self.env_key, c, seeds) for c in candidates]
                                   + [(self.env_key, self.theta, seeds)])
        returns = np.array([np.mean([r.total for r in member]) for member in results[:-1]])
        self.env_steps += sum(r.steps for member in results for r in member)
        centre = results[-1]
        ranks = centred_ranks(returns)
        plus, minus = ranks[: cfg.pairs], ranks[cfg.pairs:]
        chosen = np.arange(cfg.pairs)
        if cfg.top:  # ARS V2-t: the directions whose better member did best
            chosen = np.argsort(-np.maximum(plus, minus), kind="stable")[: cfg.top]
        if cfg.optimizer == "ars":  # a step of lr along the differences over their returns' std: noise stays small
            raw_plus, raw_minus = returns[: cfg.pairs][chosen], returns[cfg.pairs:][chosen]
            spread = float(np.std(np.concatenate([raw_plus, raw_minus])))
            step = vecmat(raw_plus - raw_minus, eps[chosen]) / (len(chosen) * (spread if spread > 0.0 else 1.0))
            self.theta = self.theta + cfg.lr * (step - cfg.weight_decay * self.theta)
        else:
            grad = vecmat(plus[chosen] - minus[chosen], eps[chosen]) / (2 * len(chosen) * cfg.sigma)  # BLAS-free: same bits on every CPU
            grad -= cfg.weight_decay * self.theta
            self.theta = self.adam.step(self.theta, grad)
        guard = {}
        if cfg.guard:
            falls = self.guard_falls(self.theta)
            taken = falls <= self.guard_reference + cfg.guard_slack
            if not taken:
                self.theta = before
            guard = {"guard_falls": falls, "guard_reference": self.guard_reference, "update_taken": int(taken)}
        set_flat(self.net, self.theta)
        self.generation += 1
        return {
            "iteration": self.generation,
            "env_steps": self.env_steps,
            "population_mean": float(returns.mean()),
            "population_best": float(returns.max()),
            "episode_return": float(np.mean([r.total for r in centre])),
            "fall_fraction": float(np.mean([r.fell for r in centre])),
            "mean_abs_error": sum(r.abs_error for r in centre) / sum(r.steps for r in centre),
            **guard,
        }

    def state_dict(self) -> dict:
        """Everything :meth:`load_state_dict` needs to continue exactly where this left off."""
        return {"theta": self.theta.tolist(), "rng": self.rng.bit_generator.state,
                "adam": {"lr": self.adam.lr, "t": self.adam.t, "m": self.adam.m, "v": self.adam.v},
                "generation": self.generation, "env_steps": self.env_steps, "guard_reference": self.guard_reference}

    def load_state_dict(self, state: dict) -> None:
        self.theta = np.asarray(state["theta"])
        set_flat(self.net, self.theta)
        self.rng.bit_generator.state = state["rng"]
        self.adam = Adam(**state["adam"])
        self.generation, self.env_steps = state["generation"], state["env_steps"]
        self.guard_reference = state.get("guard_reference")  # (a checkpoint written before the guard: None)

    @property
    def iteration(self) -> int:
        return self.generation
