"""``RabbitHZD-Learned-v1``: the deployed learned controller's closed loop as a Gymnasium env,
its network the agent. Built by :func:`rabbit_policy.spec.build` from a controller spec (the
packaged ``learned.yaml`` by default), so every stage the shipped controller carries (the
speed integral with its windup decay and feed-forward, the residual on the calibrated
library, the policy blend, the recovery rule as an overlay, the controller's at-once
settings) acts while the agent learns; the agent stands in for the network only.

    import gymnasium, rabbit_policy
    env = gymnasium.make("RabbitHZD-Learned-v1")                    # the packaged learned spec
    env = gymnasium.make("RabbitHZD-Learned-v1", spec="out/learned.yaml", distribution="moderate")

One env step is one decision (every ``decision.period_ticks`` ticks of the spec). The
observation is what the network sees (:meth:`NetworkPolicy.network_input`: the paper's three
inputs, the speed integral, the last action; noise on the measured speeds as the
distribution says); the action, in [-1, 1] (21), is the network's output normalised to its
bounds (:meth:`~rabbit_policy.runtime.forward.NetworkForward.physical`). The first step of
an episode decides the gait the walk starts on (as the deployed network answers (v, v, 0)
before the first state), so an agent that gives the network's own outputs walks exactly as
the deployed controller: bit for bit, tested. Rewards, ``info``, the episode distributions
and the privileged state are :class:`~rabbit_policy.learning.env.RabbitHZDEnv`'s.

## Version history

* v1: the spec's loop (v0, ``RabbitHZD-Shipped-v0``, trains the network without the rules the
  shipped controller carries).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np

from rabbit_hzd_controller.controller import ControllerConfig
from rabbit_policy.experiment.loop import ClosedLoop
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.learning.env import RabbitHZDEnv, reward_terms
from rabbit_policy.runtime.actions import ActionBounds, clip
from rabbit_policy.runtime.gait_command import reset_policy
from rabbit_policy.runtime.speed_window import Observation
from rabbit_policy.spec import load_controller, packaged_spec
from rabbit_sim.physics.model import load_model
from rabbit_sim.physics.simulation import StopRules

DEFAULT_STEPS = 500
"""Decisions per episode (10 s of sim time at 20 ticks)."""
MIN_SWITCH_TIME = 0.1
"""s: the paper's command change comes no earlier (a schedule's entries are 0.1 s apart at least)."""


class SpecEnv(RabbitHZDEnv):
    """See the module docstring. ``spec``: a learned controller spec file (None: the packaged
    one); the rest as :class:`RabbitHZDEnv`'s (its network, action and memory arguments come
    from the spec)."""

    def __init__(self, spec: str | Path | None = None, model="paper", speed_range: tuple[float, float] = (0.7, 1.5),
                 max_steps: int = DEFAULT_STEPS, fall_penalty: float = -50.0, alive_bonus: float = 0.0,
                 slow_penalty: float = 0.0, reward: str = "tracking", rules: StopRules = StopRules(),
                 distribution="paper", render_mode: str | None = None) -> None:
        self.spec_file = Path(spec) if spec else packaged_spec("learned")
        self.policy = load_controller(self.spec_file)
        controller_spec = self.policy.spec
        if controller_spec.kind != "learned" or not controller_spec.decision.period_ticks:
            raise ValueError(f"{self.spec_file}: the env learns a learned spec that decides every N ticks")
        super().__init__(model=model, speed_range=speed_range, max_steps=max_steps,
                         window=controller_spec.decision.window_ticks, fall_penalty=fall_penalty,
                         alive_bonus=alive_bonus, slow_penalty=slow_penalty, reward=reward, rules=rules,
                         decision_period=controller_spec.decision.period_ticks, distribution=distribution,
                         render_mode=render_mode)
        self.memory = None  # the policy's own memory is the one that runs
        self.residual = None
        self._controller = ControllerConfig(**self.policy.controller_settings)
        inputs = self.policy.forward.inputs
        limit = self.policy.memory.config.integral.limit if self.policy.memory is not None else 3.0
        low = [speed_range[0], -3.0, -3.0, -limit] + [-1.0] * (inputs - 4)
        high = [speed_range[1], 3.0, 3.0, limit] + [1.0] * (inputs - 4)
        self.observation_space = gym.spaces.Box(np.array(low[:inputs], dtype=np.float32),
                                                np.array(high[:inputs], dtype=np.float32), dtype=np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (self.policy.forward.low.shape[0],), dtype=np.float32)
        self.bounds = ActionBounds(self.policy.forward.low.astype(float), self.policy.forward.high.astype(float))

    def _input(self, observation: Observation) -> np.ndarray:
        """The network's input for ``observation``, noise on the measured speeds first."""
        noise = self.distribution.observation_noise
        if noise > 0.0:
            measured = np.array(observation.as_tuple()[1:]) + self.np_random.normal(0.0, noise, 2)
            observation = replace(observation, mean_speed=float(measured[0]), mean_error=float(measured[1]))
        x = np.asarray(self.policy.network_input(observation), dtype=np.float32)
        return clip(x, self.observation_space.low, self.observation_space.high).astype(np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """A new walk. ``options``: ``desired_speed``/``next_speed`` (m/s) as the v0 env's, or
        ``scenario``: a :class:`~rabbit_policy.experiment.scenario.Scenario` to walk (its
        schedule, pushes, model and delay; an evaluation's episode)."""
        gym.Env.reset(self, seed=seed)
        options = options or {}
        lo, hi = self.speed_range
        first, second = (float(self.np_random.uniform(lo, hi)) for _ in range(2))
        self._switch_step = int(self.np_random.integers(self.max_steps // 4, 3 * self.max_steps // 4 + 1))
        if "scenario" in options:
            scenario = options["scenario"]
            if not isinstance(scenario, Scenario):
                raise ValueError(f"reset option scenario must be a Scenario, got {scenario!r}")
            self._push_impulse = sum(p.force_x * p.duration for p in scenario.pushes)
        else:
            self.desired_speed = self._speed_option(options, "desired_speed", first)
            self._next_speed = self._speed_option(options, "next_speed", second)
            scenario = self._draw_scenario()
            if self.distribution.command_interval is None:  # the paper's one change, at its step
                when = max(self._switch_step * self.decision_period / 1000.0, MIN_SWITCH_TIME)
                scenario = replace(scenario, schedule=((0.0, self.desired_speed), (when, self._next_speed)))
        self._scenario = replace(scenario, rules=self.rules, window=self.window_size)
        self.desired_speed = self._scenario.initial_speed
        self._model = self._models.get(self._scenario.model) or self._models.setdefault(
            self._scenario.model, load_model(self._scenario.model))
        self._loop = None  # built by the first step, on the start gait the agent decides
        self._steps = 0
        reset_policy(self.policy)
        self._start = Observation(self.desired_speed, self.desired_speed, 0.0)
        return self._input(self._start), {"desired_speed": self.desired_speed, "privileged": None}

    def step(self, action):
        if not hasattr(self, "_start"):
            raise RuntimeError("call reset() before step()")
        physical = self.policy.forward.physical(clip(np.asarray(action, dtype=np.float32), -1.0, 1.0))
        rejected = False
        if self._loop is None:  # the start gait: the walk begins on it
            command = self.policy.start_from(self._start, physical)
            self._loop = ClosedLoop(self._scenario, start=command, controller=self._controller, model=self._model,
                                    observe_speed=True, decision_period=self.decision_period, decide_outside=True)
        else:
            observation, self._loop.pending = self._loop.pending, None
            command = self.policy.decide(observation, physical)
            rejected = not self._loop.apply_gait(command)
        loop = self._loop
        stop = loop.run(max_ticks=self._max_ticks(), until_decision=True)
        fell, stalled = loop.fell, loop.stalled
        self._steps += 1
        self.desired_speed = loop.desired_speed
        terminated = bool(stop or fell or stalled)
        clean = loop.pending if loop.pending is not None else replace(loop.observation(moving=True),
                                                                        body=loop.body_state())
        obs = self._input(clean) if loop.pending is not None else np.zeros(self.observation_space.shape,
                                                                            dtype=np.float32)
        mean_speed = float(clean.mean_speed)
        truncated = not terminated and self._steps >= self.max_steps
        terms = reward_terms(self.reward, loop, mean_speed, self.desired_speed, terminated, truncated,
                             self.fall_penalty, self.alive_bonus, self.slow_penalty)
        reward = sum(terms.values())
        info = {"desired_speed": self.desired_speed, "mean_speed": mean_speed, "fell": fell, "stalled": stalled,
                "rejected": rejected, "time": loop.time, "privileged": self.privileged_state(), **terms}
        if self.render_mode == "human":
            self.render()
        return obs, float(reward), terminated, truncated, info

    def _max_ticks(self) -> int:
        """Ticks a step may run at most: to its decision, which is due every period (a bound, not the rule)."""
        return 2 * self.decision_period + 1


def make_env(kwargs: dict) -> RabbitHZDEnv:
    """The env of :meth:`~rabbit_policy.learning.env.EpisodeConfig.env_kwargs`: a controller
    spec's loop (:class:`SpecEnv`) when they name one, else :class:`RabbitHZDEnv`."""
    return SpecEnv(**kwargs) if kwargs.get("spec") else RabbitHZDEnv(**kwargs)
