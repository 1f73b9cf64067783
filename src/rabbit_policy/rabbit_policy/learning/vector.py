"""PPO's parallel environments on either execution backend, with the same results.

* ``local``: Gymnasium's ``AsyncVectorEnv`` (one forked process per environment).
* ``ray``: :class:`RayVectorEnv`, one Ray actor per environment, spread over the cluster.

Both follow Gymnasium's same-step autoreset rule (an episode that ends is reset in the
same ``step``; its last observation and info go in ``final_obs``/``final_info``), seed
environment ``i`` with ``seed + i`` on ``reset(seed=...)`` and merge the infos with
Gymnasium's own ``VectorEnv._add_info``, so a PPO run gives the same numbers on both.
"""

from __future__ import annotations

import copy
from typing import Any, Callable

import gymnasium as gym
import numpy as np
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array

EnvFactory = Callable[[], gym.Env]


class EnvWorker:
    """One environment with same-step autoreset, as ``AsyncVectorEnv``'s worker runs it
    (the body of a Ray actor)."""

    def __init__(self, factory: EnvFactory) -> None:
        self.env = factory()

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[Any, dict]:
        return self.env.reset(seed=seed, options=options)

    def step(self, action: np.ndarray) -> tuple[Any, float, bool, bool, dict]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        if terminated or truncated:
            reset_obs, reset_info = self.env.reset()
            info = {"final_info": info, "final_obs": obs, **reset_info}
            obs = reset_obs
        return obs, reward, terminated, truncated, info

    def close(self) -> None:
        self.env.close()


class EnvWorkerDied(RuntimeError):
    """An environment's Ray actor (or its node) died: the episodes in progress are lost."""


class RayVectorEnv(gym.vector.VectorEnv):
    """``len(factories)`` environments as Ray actors of ``backend`` (a connected
    :class:`rabbit_policy.parallel.RayBackend`); the calls to all environments of a step run
    in parallel and their results are gathered in environment order."""

    metadata = {"autoreset_mode": gym.vector.AutoresetMode.SAME_STEP}

    def __init__(self, factories: list[EnvFactory], backend) -> None:
        probe = factories[0]()  # the spaces, as AsyncVectorEnv takes them from a dummy environment
        self.single_observation_space = probe.observation_space
        self.single_action_space = probe.action_space
        probe.close()
        self.num_envs = len(factories)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._backend = backend
        # no CPU reserved: an idle actor must not block the evaluation tasks that run between
        # PPO iterations on the same CPUs (they would wait for each other for ever)
        self._actors = [backend.actor(EnvWorker, f, num_cpus=0) for f in factories]

    def _gather(self, refs: list) -> list:
        try:
            return self._backend.get(refs)
        except self._backend.actor_errors as exc:
            raise EnvWorkerDied(f"a PPO environment worker died ({type(exc).__name__}); its episode is lost: "
                                "resume from the last checkpoint (--resume)") from None

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict | None = None):
        seeds = [seed + i for i in range(self.num_envs)] if isinstance(seed, int) else (seed or [None] * self.num_envs)
        results = self._gather([a.reset.remote(s, options) for a, s in zip(self._actors, seeds)])
        infos: dict = {}
        for i, (_obs, info) in enumerate(results):
            infos = self._add_info(infos, info, i)
        return self._observations([obs for obs, _info in results]), infos

    def step(self, actions: np.ndarray):
        results = self._gather([a.step.remote(np.asarray(act)) for a, act in zip(self._actors, actions)])
        infos: dict = {}
        for i, result in enumerate(results):
            infos = self._add_info(infos, copy.deepcopy(result[4]), i)  # Ray's arrays are read-only
        return (self._observations([r[0] for r in results]),
                np.array([r[1] for r in results], dtype=np.float64),
                np.array([r[2] for r in results], dtype=np.bool_),
                np.array([r[3] for r in results], dtype=np.bool_),
                infos)

    def _observations(self, items: list) -> np.ndarray:
        out = create_empty_array(self.single_observation_space, self.num_envs)
        return concatenate(self.single_observation_space, items, out)

    def close_extras(self, terminate: bool = False, **_kwargs) -> None:
        """Stop the actors (``terminate``: at once, without closing the environments);
        ``close()`` calls this once."""
        if not terminate:
            try:
                self._backend.get([a.close.remote() for a in self._actors])
            except self._backend.actor_errors:
                pass  # a dead actor has nothing left to close
        for actor in self._actors:
            self._backend.kill(actor)
        self._actors = []


def make_vector_env(factories: list[EnvFactory], backend=None) -> gym.vector.VectorEnv:
    """The environments on ``backend``'s kind: Ray actors on a Ray backend, else an
    ``AsyncVectorEnv`` of forked processes (same-step autoreset on both)."""
    if backend is not None and backend.kind == "ray":
        return RayVectorEnv(factories, backend)
    return gym.vector.AsyncVectorEnv(factories, context="fork", autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
