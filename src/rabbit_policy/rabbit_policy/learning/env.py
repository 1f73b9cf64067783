"""``RabbitHZD-v0``: the paper's HZD-RL learning problem as a Gymnasium environment.

    import gymnasium, rabbit_policy
    env = gymnasium.make("RabbitHZD-v0")                       # the paper's episodes, 60 walking steps
    env = gymnasium.make("RabbitHZD-v0", decision_period=20, distribution="robust",
                         max_episode_steps=500, render_mode="rgb_array")

No ROS inside: the same MuJoCo model (:mod:`rabbit_sim`) and the same HZD controller core
(:class:`HZDController`) the nodes run, in the same closed loop
(:class:`~rabbit_policy.experiment.loop.ClosedLoop`) as walk.py and the evaluations.

## Action space

``Box(-1, 1, (21,), float32)``, normalised: ``a = -1`` is the lower physical bound, ``+1`` the
upper (:meth:`ActionBounds.to_physical`; ``env.unwrapped.bounds`` holds them). The physical
action is the gait:

| index | action | physical bounds |
|-------|--------|-----------------|
| 0-19  | the 20 free Bezier coefficients alpha (rad, joint waypoints; the core's order, ``rabbit_hzd_controller.alpha``: output ``i % 4`` = stance hip, stance knee, swing hip, swing knee) | the classic gaits' range widened by ``margin`` (0.15 rad), clipped to the controller's joint-waypoint bounds |
| 20    | Kd, the PD derivative gain (N m s/rad) | 20 to 150 |

Decision timing as in the node stack: with ``decision_period`` 0 (the default) one env step is
one walking step and the action is the gait for the *next* step (queued at the touchdown);
with N > 0 one env step is N control ticks (1 ms each) and the action applies at once, blended
in (``HZDController.apply_now``), as the paper evaluates its network every simulation step.
An action the controller rejects (e.g. an implied step shorter than 5 cm) leaves the previous
gait in force, as the controller node does; ``info["rejected"]`` says so.

## Observation space

``Box((v_min, -3, -3), (v_max, 3, 3), (3,), float32)``, the paper's three inputs (m/s):

| index | observation | unit |
|-------|-------------|------|
| 0 | commanded speed v_d | m/s |
| 1 | mean hip speed over the last step (touchdown to touchdown), or with a decision period the moving average over the last step's duration (:class:`~rabbit_policy.runtime.speed_window.SpeedWindow`) | m/s |
| 2 | mean of (v_d - hip speed) over the same ticks | m/s |

Indices 1 and 2 carry Gaussian noise of ``distribution.observation_noise`` (m/s; the robust
distribution: 0.02). ``features="memory"`` (the learning issue's ablation row b,
:mod:`rabbit_policy.runtime.memory`) appends the integral of the speed error (index 3, m,
within +-0.2: anti-windup) and the last action (indices 4-24, normalised): a 25-vector.
``features="body"`` (row c; needs a decision period) appends to those the body state at the
decision (:mod:`rabbit_policy.runtime.body`: torso pitch (rad) and rate (rad/s), phase and
its rate (1/s), hip velocity (m/s); noise-free): a 30-vector.

With ``action="residual"`` (row d, :mod:`rabbit_policy.runtime.actions`) the action is a
residual on the calibrated library's gait at the commanded speed: -1..1 maps onto
+-0.1 rad per coefficient and +-20 N m s/rad on Kd, and the action 0 is the classic
controller's gait; ``env.unwrapped.bounds`` then holds the residual's bounds. With
``integral_gain`` > 0 (1/s; memory or body features) the library's gait is the one for
v_d + gain x the memory's integral (index 3, then bounded so that the offset stays within
+-0.2 m/s): the action 0 is then the classic controller with Westervelt's speed integral.

## Rewards

| term (``info`` key) | value |
|---------------------|-------|
| ``reward_tracking`` | ``reward="tracking"`` (the default): ``-(mean hip speed - v_d)^2`` per env step (the paper; the true speed, without noise) |
| ``reward_reach`` | ``reward="evaluation"``: 0 until the episode is truncated, then each commanded change's graded reach, ``1 - t / 4 s`` when reached after t <= 4 s (the evaluation's reach rule), else 0 |
| ``reward_settle`` | ``reward="evaluation"``: 0 until the episode is truncated, then each segment's ``1 / (1 + (e / 0.03)^2)`` for its mean speed's error e (m/s): every change weighted alike; a fall pays neither, so it returns ``fall_penalty`` alone, below any walk |
| ``reward_fall`` | ``fall_penalty`` once, when the episode ends by a fall or stall (0 otherwise): with only negative rewards an early end would otherwise pay |
| ``reward_alive`` | ``alive_bonus`` per env step that did not end the episode (0 by default): a survival term, so that a fall forfeits the rest of the episode's bonus and a survived push pays more than its tracking costs |
| ``reward_slow`` | ``slow_penalty`` x (:data:`SLOW_HIP_SPEED` - hip velocity) per env step whose hip velocity (m/s, world x, at its end) is below that speed, 0 otherwise (0 by default): a margin that grows as a pushed robot nears a stall, smooth in the policy's parameters where the fall penalty is all or nothing (docs/learning.md, 2026-11-27 (third)) |

The reward is their sum. ``info`` also holds ``desired_speed``, ``mean_speed`` (m/s), ``fell``,
``stalled``, ``rejected``, ``time`` (sim s) and ``privileged`` (also in the reset's info): the
state a critic may see and the policy may not (:data:`PRIVILEGED_STATE`, in that order: the body
state, the hip height (m), the time since the last touchdown (s), the push acting now (N, world
x), the episode's push impulse (N s, signed; 0 without one) and whether it is still to come, the
foot friction, the torso mass scale, the ``drives`` variant (1) and the torque delay (s)). PPO's
privileged critic reads it (:mod:`rabbit_policy.learning.ppo`).

## Starting state and episodes

The robot starts at phase 0 of the classic gait nearest v_d, on it, at its first touchdown.
v_d is drawn uniformly from ``speed_range`` and redrawn once, at a step drawn uniformly from
the middle half of the episode (the paper's episodes); ``reset(options={"desired_speed": v0,
"next_speed": v1})`` fixes the two commands. ``distribution`` (:class:`EpisodeDistribution`,
:data:`DISTRIBUTIONS`: ``paper``, ``broad``, ``moderate``, ``robust``, ``pushes``, ``recovery``) widens that: a new command every 2-5 s
of sim time, a push of random impulse, direction and time, a model drawn from foot
frictions, torso masses, the ``drives`` variant and torque delays, observation noise.
Where a drawn model and delay stall or fall on the very first step (about 1 in 750 robust
draws: 0.72 m/s on friction 0.4), the reset draws them again (:data:`START_ATTEMPTS`): an
episode starts walking.

## Episode end

Terminated by the closed loop's stop rules: a fall (|torso pitch| >= 0.5 rad or the hip height
leaves (0.6, 0.8] m) or a stall (no touchdown for 2 s; with ``rules=StopRules(roll_back_after=T)``
also as soon as the hip has rolled back behind its stance foot for T s, the early failure rule
the recovery preset trains with). Truncated after ``max_steps`` env
steps (60), the spec's ``max_episode_steps`` too; ``max_steps`` also places the command changes
and the push inside the episode. Gymnasium's ``make`` gives ``max_episode_steps`` to its
TimeLimit wrapper only, so every id carries :class:`EpisodeLength`, which makes the two one:
``gymnasium.make("RabbitHZD-v0", max_episode_steps=500)`` or ``max_steps=500`` alone gives
500-step episodes (both given: both as given). The presets' ids (``RabbitHZD-Shipped-v0``,
``RabbitHZD-Recovery-v0``: :data:`PRESETS`) are registered with 500.

## Arguments

| argument | default | meaning |
|----------|---------|---------|
| ``model`` | ``"paper"`` | the MJCF variant or a :class:`~rabbit_sim.physics.model.ModelOptions` |
| ``speed_range`` | (0.7, 1.5) | commands are drawn from it (m/s) |
| ``max_steps`` | 60 | env steps per episode (see Episode end) |
| ``window`` | 1000 | speed-window length (ticks) |
| ``fall_penalty`` | -10.0 | see Rewards |
| ``alive_bonus`` | 0.0 | see Rewards |
| ``rules`` | ``StopRules()`` | fall and stall limits |
| ``margin`` | 0.15 | widening of the coefficient bounds (rad) |
| ``decision_period`` | 0 | ticks per env step (0: one walking step) |
| ``distribution`` | ``"paper"`` | the episodes (see above) |
| ``features`` | ``"paper"`` | the observation: the paper's three, ``"memory"`` or ``"body"`` (see Observation space) |
| ``action`` | ``"direct"`` | the action: the gait, or ``"residual"`` on the library (see Observation space) |
| ``integral_gain`` | 0.0 | residual only: the base gait at v_d + gain x the speed integral (1/s; see Observation space) |
| ``integral_band`` | 0.0 | memory or body features: the speed integral is held while the speed error is this or more (m/s; 0 = never; :mod:`rabbit_policy.runtime.speed_integral`) |
| ``integral_clip`` | 0.0 | memory or body features: the error the speed integral adds is clipped to +-this (m/s; 0 = not clipped) |
| ``integral_windup_decay`` | 0.0 | memory or body features: after a command change, what the speed integral wound up decays (time constant 1 s) once the hip has passed the new command, until this long after the change (s; 0 = never; :class:`~rabbit_policy.runtime.speed_integral.WindupDecay`) |
| ``residual_base`` | ``"classic"`` | residual only: what it adds to, the library's gait (``classic``) or the recovery controller's decision (``recovery``; needs a decision period; the controller then applies gaits at once), or that scaled by the recovery rule's weight at the decision (``recovery_gated``: zero until something slows the hip) |
| ``render_mode`` | None | ``"rgb_array"`` (offscreen, a side camera following the hip; needs an OpenGL backend: ``MUJOCO_GL=egl`` on a headless machine) or ``"human"`` (MuJoCo's viewer; needs a display) |

## Version history

* v0: the paper's problem; normalised actions, reward terms in ``info``, render modes, the
  spec's ``max_episode_steps`` (this version).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import gymnasium as gym
import numpy as np

from rabbit_hzd_controller.alpha import N_FREE, expand_alpha, reduce_alpha
from rabbit_hzd_controller.controller import ControllerConfig
from rabbit_msgs_py.cli import option
from rabbit_msgs_py.decision_ticks import decision_ticks
from rabbit_policy.evaluation.push_recovery import classic_margin
from rabbit_policy.experiment.loop import ClosedLoop
from rabbit_policy.experiment.options import decision_ticks_option
from rabbit_policy.experiment.scenario import PhasePush, Push, Scenario
from rabbit_policy.registration import ENV_ID, MAX_EPISODE_STEPS, register
from rabbit_policy.runtime.actions import (ACTIONS, RESIDUAL_BASES, ActionBounds,  # noqa: F401  (ActionBounds re-exported)
                                           ResidualAction, clip, residual_gate, residual_sum_bounds)
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.memory import FEATURES, MemoryConfig, SpeedMemory, check_features
from rabbit_policy.runtime.speed_integral import WindupDecay, check_gain
from rabbit_policy.runtime.policies import DEFAULT_DECISION_WINDOW, GaitCommand, controller_settings, reset_policy
from rabbit_policy.runtime.recovery import RecoveryConfig
from rabbit_policy.spec.build import residual_base as rule_base
from rabbit_policy.spec.schema import load_spec
from rabbit_policy.runtime.speed_window import Observation
from rabbit_sim.physics.model import ModelOptions, load_model
from rabbit_sim.physics.simulation import StopRules

START_ATTEMPTS = 10
"""Scenarios drawn at a reset until the starting gait's first step completes (about 1 in 750
robust draws stalls there: 0.72 m/s on friction 0.4); the episodes are those that start."""

PRIVILEGED_STATE = ("torso_pitch", "torso_pitch_rate", "phase", "phase_rate", "hip_velocity", "hip_height",
                    "since_touchdown", "push_force", "push_impulse", "push_pending", "friction",
                    "torso_mass_scale", "drives", "torque_delay")
"""The entries of ``info["privileged"]`` (see Rewards): rad, rad/s, 1, 1/s, m/s, m, s, N, N s,
0/1, 1, 1, 0/1, s."""

PACKAGED_FRICTION = 0.8
"""The packaged foot friction coefficient (``ModelOptions.friction`` None)."""

DEFAULT_MAX_STEPS = MAX_EPISODE_STEPS
"""Env steps per episode unless the spec (``max_episode_steps``) or ``max_steps`` says otherwise."""

SLOW_HIP_SPEED = 0.25
"""m/s: the hip velocity below which ``slow_penalty`` pays (undisturbed walking at 0.7 m/s keeps
the hip faster through the whole step; a push that nearly stalls the robot brings it to 0 and
below)."""


@dataclass(frozen=True)
class EpisodeDistribution:
    """What an episode draws besides its first command (times s, speeds m/s, impulses N s).

    command_interval: a new uniform command every U(interval) s of sim time (the first
        change to the ``next_speed`` reset option if given); None: the paper's one change.
    push_probability, max_impulse, push_duration: with this probability the episode has one
        push on the torso, impulse uniform in [-max, max] (with ``min_impulse`` > 0: a
        magnitude uniform in [min, max], either way), at a uniform time from 1 s to 1 s
        before the episode's nominal end.
    push_timing: ``time`` (the push at that sim time) or ``phase`` (a
        :class:`~rabbit_policy.experiment.scenario.PhasePush`: at a uniform phase of the first
        step after that time, the phase measured on the episode's own touchdowns, so every
        member of an ES population is hit at the same point of its step: common random
        numbers in phase, not only in time).
    relative_impulse: min/max impulse are multiples of classic HZD's push margin
        (:data:`~rabbit_policy.evaluation.push_recovery.CLASSIC_MARGINS`) at the command in force at the push's time, in its direction:
        a curriculum around the margin at every speed.
    backward_fraction: with ``relative_impulse``, the probability that the push is backward
        (else forward; otherwise either way is equally likely).
    backward_scale: with ``relative_impulse``, a backward push's multiples of the margin are
        ``backward_scale`` x [min, max] (the recovery rule carries backward pushes far beyond
        classic's margin, so the pushes whose outcome is decided lie further out there).
    frictions, torso_mass_scales, variants, torque_delays: the model and the delay, each
        drawn uniformly from its tuple (repeat an entry to weight it; None friction: the
        packaged one).
    observation_noise: std (m/s) of Gaussian noise added to the two measured inputs (mean
        hip speed and mean speed error) of every observation, not to the command."""

    command_interval: tuple[float, float] | None = None
    push_probability: float = 0.0
    max_impulse: float = 0.0
    min_impulse: float = 0.0
    push_duration: float = 0.1
    push_timing: str = "time"
    relative_impulse: bool = False
    backward_fraction: float = 0.5
    backward_scale: float = 1.0
    frictions: tuple[float | None, ...] = (None,)
    torso_mass_scales: tuple[float, ...] = (1.0,)
    variants: tuple[str, ...] = ("paper",)
    torque_delays: tuple[float, ...] = (0.0,)
    observation_noise: float = 0.0

    def __post_init__(self) -> None:
        if self.push_timing not in ("time", "phase"):
            raise ValueError(f"push_timing must be time or phase, got {self.push_timing!r}")
        if not 0.0 <= self.backward_fraction <= 1.0:
            raise ValueError(f"backward_fraction must be in [0, 1], got {self.backward_fraction}")
        if not self.backward_scale > 0.0:
            raise ValueError(f"backward_scale must be > 0, got {self.backward_scale}")
        if not 0.0 <= self.min_impulse <= self.max_impulse:
            raise ValueError(f"impulses must satisfy 0 <= min_impulse <= max_impulse, got {self.min_impulse}, "
                             f"{self.max_impulse}")


DISTRIBUTIONS = {
    "paper": EpisodeDistribution(),
    "broad": EpisodeDistribution(command_interval=(2.0, 5.0), push_probability=0.5, max_impulse=15.0,
                                 frictions=(None, None, 0.6, 0.5, 0.4), torso_mass_scales=(0.85, 1.0, 1.0, 1.15),
                                 variants=("paper", "paper", "drives"), torque_delays=(0.0, 0.0, 0.002, 0.003)),
    # a step towards robust (a curriculum's middle): pushes up to 12 N s, delays up to 2 ms, milder model errors
    "moderate": EpisodeDistribution(command_interval=(2.0, 5.0), push_probability=0.5, max_impulse=12.0,
                                    frictions=(None, None, 0.6, 0.5), torso_mass_scales=(0.9, 1.0, 1.0, 1.1),
                                    variants=("paper", "paper", "drives"), torque_delays=(0.0, 0.0, 0.001, 0.002),
                                    observation_noise=0.02),
    # what the learning issue judges on (checks 1-6): pushes up to 20 N s both ways, delays 0-4 ms, noisy speeds
    "robust": EpisodeDistribution(command_interval=(2.0, 5.0), push_probability=0.8, max_impulse=20.0,
                                  frictions=(None, None, 0.6, 0.5, 0.4), torso_mass_scales=(0.85, 1.0, 1.0, 1.15),
                                  variants=("paper", "paper", "drives"),
                                  torque_delays=(0.0, 0.0, 0.001, 0.002, 0.003, 0.004), observation_noise=0.02),
    # check 4 as a training signal: one push in every episode, 6-20 N s either way (classic survives
    # backward pushes of about 8-10 N s, forward about 24), commands every 2-5 s, the nominal model
    "pushes": EpisodeDistribution(command_interval=(2.0, 5.0), push_probability=1.0, min_impulse=6.0,
                                  max_impulse=20.0, observation_noise=0.02),
    # the push-recovery issue's training signal: a push in every episode at a phase of a step
    # (common random numbers in phase), 0.8-2.2x classic's margin at the speed in force (two
    # thirds backward, where the margin binds), commands every 2-5 s, mild model errors (the
    # moderate ones made unpushed episodes fall: noise in the ranks that says nothing of pushes;
    # measured in commit d3e8074)
    "recovery": EpisodeDistribution(command_interval=(2.0, 5.0), push_probability=1.0, push_timing="phase",
                                    relative_impulse=True, min_impulse=0.8, max_impulse=2.2, backward_fraction=2 / 3,
                                    frictions=(None, None, 0.6), torso_mass_scales=(0.9, 1.0, 1.0, 1.1),
                                    variants=("paper", "paper", "drives"), torque_delays=(0.0, 0.0, 0.001, 0.002),
                                    observation_noise=0.02),
    # the evaluation's trials as a training signal (reward evaluation): commands every 2-5 s, half
    # the episodes pushed at a phase of a step (common random numbers in phase), 0.5-1.5x
    # classic's margin either way, the nominal model with delays up to 2 ms (no friction or
    # drives episodes that no policy can pass: they held most of moderate's spread, the
    # learning issue's measurement)
    "changes": EpisodeDistribution(command_interval=(2.0, 5.0), push_probability=0.5, push_timing="phase",
                                   relative_impulse=True, min_impulse=0.5, max_impulse=1.5,
                                   torque_delays=(0.0, 0.0, 0.001, 0.002), observation_noise=0.02),
    # changes' episodes with as many forward pushes again: three episodes in four pushed, two
    # thirds of the pushes forward (changes: one episode in four pushed forward, as many backward).
    # Every counted network traded forward pushes at the slowest and fastest speeds for backward
    # pushes and changes; here the return sees twice the forward falls (docs/learning.md,
    # 2026-12-07 (fourth): the forward losses grew)
    "forward": EpisodeDistribution(command_interval=(2.0, 5.0), push_probability=0.75, push_timing="phase",
                                   relative_impulse=True, min_impulse=0.5, max_impulse=1.5, backward_fraction=1 / 3,
                                   torque_delays=(0.0, 0.0, 0.001, 0.002), observation_noise=0.02),
    # changes' commands with a push in every episode where the screen decides its outcome:
    # forward 0.8-1.6x classic's margin, backward 1.2-2.4x (the screen pushes at 1.0 / 1.3x and
    # 1.5 / 2.0x), either way alike, at a phase of a step (the counted preset's seeds traded
    # forward pushes for backward ones: in changes one episode in four is pushed forward and few
    # of those are decided; docs/learning.md, 2026-12-02 (second))
    # the forward-push guard of an ES run (ESConfig.guard): changes' commands, every episode pushed
    # forward at a phase of a step, 0.9-1.4x classic's margin (the screen pushes forward at 1.0x and
    # 1.3x), the nominal model; an update that falls more often on a fixed set of these than the start
    # is not taken (a constraint, not a reward term: docs/learning.md, 2026-12-07 (fifth))
    "forward_guard": EpisodeDistribution(command_interval=(2.0, 5.0), push_probability=1.0, push_timing="phase",
                                         relative_impulse=True, min_impulse=0.9, max_impulse=1.4,
                                         backward_fraction=0.0, torque_delays=(0.0, 0.0, 0.001, 0.002),
                                         observation_noise=0.02),
    # the guard set drawn as the screen's forward trials are (ESConfig.guard_set "screen": a steady
    # command at one of the screen's push speeds, a forward push at 1.0-1.3x classic's margin at a
    # phase the screen does not use, no delay, no noise; docs/learning.md, 2026-12-07 (sixth))
    "screen_forward": EpisodeDistribution(command_interval=None, push_probability=1.0, push_timing="phase",
                                          relative_impulse=True, min_impulse=1.0, max_impulse=1.3,
                                          backward_fraction=0.0),
    "decided": EpisodeDistribution(command_interval=(2.0, 5.0), push_probability=1.0, push_timing="phase",
                                   relative_impulse=True, min_impulse=0.8, max_impulse=1.6, backward_scale=1.5,
                                   torque_delays=(0.0, 0.0, 0.001, 0.002), observation_noise=0.02),
}
"""Named episode distributions (``scripts/train.py --episodes``)."""


REWARDS = ("tracking", "evaluation")
"""``reward``: ``tracking`` (the paper's per-step squared speed error) or ``evaluation`` (what
the evaluation counts, paid when the episode ends: :func:`reward_terms`)."""


def reward_terms(reward: str, loop: ClosedLoop, mean_speed: float, desired_speed: float, terminated: bool,
                 truncated: bool, fall_penalty: float, alive_bonus: float, slow_penalty: float) -> dict[str, float]:
    """One env step's reward terms (their sum is the reward; ``info`` holds each). Both
    rewards: ``reward_fall`` (``fall_penalty`` when the step ends the episode by a fall or
    stall), ``reward_alive`` and ``reward_slow`` (see the module docstring). ``tracking`` adds
    ``reward_tracking``, -(``mean_speed`` - ``desired_speed``)^2 (m/s) every step.
    ``evaluation`` adds ``reward_reach`` and ``reward_settle``, 0 until the episode is
    truncated, then the walk's graded reach and settle scores
    (:meth:`~rabbit_policy.experiment.result.WalkResult.tracking_scores`: every change weighted
    alike): with ``alive_bonus`` and ``slow_penalty`` at 0 a walk returns >= 0 and a fall
    exactly ``fall_penalty`` (< 0), below any walk."""
    terms = {"reward_fall": fall_penalty if terminated else 0.0,
             "reward_alive": 0.0 if terminated else alive_bonus,
             "reward_slow": slow_penalty * max(0.0, SLOW_HIP_SPEED - float(loop.data.qvel[0]))}
    if reward == "tracking":
        return {"reward_tracking": -((mean_speed - desired_speed) ** 2), **terms}
    reach, settle = loop.result().tracking_scores() if truncated and not terminated else (0.0, 0.0)
    return {"reward_reach": reach, "reward_settle": settle, **terms}


def check_reward(reward: str, fall_penalty: float) -> None:
    """Raise ``ValueError`` unless ``reward`` is one of :data:`REWARDS` (``evaluation`` with a
    ``fall_penalty`` < 0, so that a fall returns less than any walk)."""
    if reward not in REWARDS:
        raise ValueError(f"reward must be one of {REWARDS}, got {reward!r}")
    if reward == "evaluation" and not fall_penalty < 0.0:
        raise ValueError(f"reward evaluation needs fall_penalty < 0 (a fall below any walk), got {fall_penalty}")


def check_integral_gain(gain: float, action: str) -> None:
    """Raise ``ValueError`` unless ``gain`` (1/s) is finite and >= 0, and 0 unless the action is
    a residual (the integral offsets the residual's base gait)."""
    if check_gain(gain, "integral_gain") and action != "residual":
        raise ValueError("integral_gain offsets a residual's base gait: it needs action residual")


@dataclass(frozen=True)
class EpisodeConfig:
    """What one training episode is, shared by ES and PPO (each field one ``scripts/train.py``
    option; the defaults are the first shipped policy's run, the paper's three inputs)."""

    max_steps: int = option(500, "env steps per training episode (each decision_period ticks; 0 ticks: one "
                                 "walking step)")
    decision_period: int = option(20, "ticks (1 ms) per env step, the gait applied at once; step (or 0): one env "
                                      "step per walking step, the gait for the next step", type=decision_ticks_option)
    distribution: str = option("broad", "episodes: paper (one command change), broad (commands every 2-5 s, "
                                        "pushes, model errors, torque delays), moderate (pushes up to 12 N s, delays up "
                                        "to 2 ms, noisy speeds), robust (pushes up to 20 N s, delays up to 4 ms, "
                                        "noisy speeds), pushes (a 6-20 N s push either way in every episode) or "
                                        "recovery (a push at a phase of a step in every episode, 0.8-2.2x classic's "
                                        "margin) or changes (commands every 2-5 s, half the episodes pushed at a "
                                        "phase, 0.5-1.5x classic's margin, the nominal model), forward (changes "
                                        "with three episodes in four pushed, two thirds of the pushes forward) or "
                                        "decided (changes' "
                                        "commands, every episode pushed at a phase, forward 0.8-1.6x and backward "
                                        "1.2-2.4x classic's margin) or forward_guard (every episode pushed "
                                        "forward at a phase, 0.9-1.4x: ES's guard set) or screen_forward (a steady "
                                        "command, pushed forward at a phase, 1.0-1.3x: ES's screen guard set); "
                                        "DISTRIBUTIONS",
                               choices=tuple(DISTRIBUTIONS))
    fall_penalty: float = option(-50.0, "reward once when an episode ends by a fall or stall, <= 0")
    reward: str = option("tracking", "tracking (the paper's: -(mean speed - v_d)^2 every env step) or evaluation "
                                     "(what the evaluation counts, at the episode's end: each change's graded reach "
                                     "within 4 s and each segment's settling within 0.03 m/s; a fall returns "
                                     "fall_penalty, below any walk); learning/env.py's reward_terms",
                         choices=REWARDS)
    alive_bonus: float = option(0.0, "reward per env step survived, >= 0 (a survival term: a fall forfeits the "
                                     "rest of the episode's)")
    slow_penalty: float = option(0.0, "reward per env step per m/s the hip velocity is below SLOW_HIP_SPEED "
                                      "(0.25 m/s), <= 0 (a smooth margin near a stall; 0 = none)")
    roll_back_after: float = option(0.0, "s: end the episode as a stall once the hip has been behind its stance "
                                         "foot and moving backward this long (the early failure rule, "
                                         "StopRules.roll_back_after; 0 = only no touchdown for 2 s)")
    features: str = option("paper", "the policy's inputs: paper (the three speeds), memory (+ the integral of "
                                    "the speed error and the last action; rabbit_policy.runtime.memory) or body "
                                    "(+ torso pitch and rate, phase and rate, hip velocity; needs a decision period)",
                           choices=FEATURES)
    action: str = option("direct", "the policy's output: direct (the gait) or residual (a bounded residual on the "
                                   "calibrated library at the command; zero = classic HZD; "
                                   "rabbit_policy.runtime.actions)", choices=ACTIONS)
    residual_base: str = option("classic", "action residual: what it adds to, the library's gait at the command "
                                           "(classic) or the recovery controller's decision every decision period "
                                           "(recovery: classic plus the push-recovery rule, gaits applied at once; "
                                           "recovery_gated: the same, the residual scaled by the rule's weight w)",
                                choices=RESIDUAL_BASES)
    integral_gain: float = option(0.0, "action residual with memory or body features: the base gait is the "
                                       "library's at v_d + this (1/s) x the memory's speed integral (zero residual = "
                                       "classic HZD with that speed integral; 0 = none)")
    integral_band: float = option(0.0, "memory or body features: the speed integral is held while |v_d - v| >= this "
                                       "(m/s; conditional integration against windup after a speed change; 0 = never)")
    integral_clip: float = option(0.0, "memory or body features: the speed error the integral adds is clipped to "
                                       "+-this (m/s; error saturation against windup; 0 = not clipped)")
    integral_windup_decay: float = option(0.0, "memory or body features: after a command change, what the speed "
                                               "integral wound up decays (time constant 1 s) once the hip has passed "
                                               "the new command, until this long after the change (s; 0 = never)")
    spec: str = option("", "train the network of this learned controller spec (a .yaml, docs/controller_spec.md) "
                           "in its deployed closed loop (RabbitHZD-Learned-v1), starting from its weights; the spec "
                           "sets the inputs, the action, the decision period and every rule, so features, action, "
                           "residual_base, decision_period and the integral options must be left as they are "
                           "('' = train the network these options describe)")
    seed: int = option(0, "seed of the episodes, the perturbations and the network")

    def __post_init__(self) -> None:
        if self.spec:
            spec = load_spec(self.spec)  # one line for a bad one
            if spec.kind != "learned" or spec.decision.period_ticks != self.decision_period:
                raise ValueError(f"spec {self.spec}: a learned spec deciding every decision_period "
                                 f"({self.decision_period}) ticks is needed, got {spec.kind} every "
                                 f"{spec.decision.period_ticks}")
        if not (isinstance(self.max_steps, int) and self.max_steps >= 1):
            raise ValueError(f"max_steps must be a whole number >= 1, got {self.max_steps!r}")
        decision_ticks(self.decision_period)  # raises for anything but 0 or N ticks
        if self.distribution not in DISTRIBUTIONS:
            raise ValueError(f"distribution must be one of {sorted(DISTRIBUTIONS)}, got {self.distribution!r}")
        if not self.fall_penalty <= 0.0:
            raise ValueError(f"fall_penalty must be <= 0, got {self.fall_penalty}")
        check_reward(self.reward, self.fall_penalty)
        if not (np.isfinite(self.alive_bonus) and self.alive_bonus >= 0.0):
            raise ValueError(f"alive_bonus must be finite and >= 0, got {self.alive_bonus}")
        check_slow_penalty(self.slow_penalty)
        StopRules(roll_back_after=self.roll_back_after)  # raises for a bad value
        if self.action not in ACTIONS:
            raise ValueError(f"action must be one of {ACTIONS}, got {self.action!r}")
        check_integral_gain(self.integral_gain, self.action)
        check_features(self.features, self.decision_period, self.integral_gain)
        check_residual_base(self.residual_base, self.action, self.decision_period, self.integral_gain)
        for name in ("integral_band", "integral_clip", "integral_windup_decay"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0.0):
                unit = "s" if name == "integral_windup_decay" else "m/s"
                raise ValueError(f"{name} must be a finite number >= 0 ({unit}; 0 = off), got {value!r}")
            if value and self.features == "paper":
                raise ValueError(f"{name} acts on the speed integral: it needs features memory or body")

    def memory_config(self, speed_range: tuple[float, float]) -> MemoryConfig | None:
        """The memory these options give a policy (None: the paper's features), for the
        library's ``speed_range`` (m/s): what the env keeps and a checkpoint records."""
        return MemoryConfig.for_features(self.features, self.decision_period, self.integral_gain, speed_range,
                                         self.integral_band or None, self.integral_clip or None,
                                         windup_decay_for(self.integral_windup_decay))

    def env_kwargs(self) -> dict:
        """The env arguments of these episodes (ES and PPO build their envs from it:
        :func:`~.spec_env.make_env`): a spec's env (:class:`~.spec_env.SpecEnv`) with ``spec``, else
        :class:`RabbitHZDEnv`'s."""
        if self.spec:
            return {"spec": self.spec, "max_steps": self.max_steps, "distribution": self.distribution,
                    "fall_penalty": self.fall_penalty, "reward": self.reward, "alive_bonus": self.alive_bonus,
                    "slow_penalty": self.slow_penalty, "rules": StopRules(roll_back_after=self.roll_back_after)}
        return {"max_steps": self.max_steps, "decision_period": self.decision_period,
                "distribution": self.distribution, "fall_penalty": self.fall_penalty, "reward": self.reward,
                "alive_bonus": self.alive_bonus, "slow_penalty": self.slow_penalty, "features": self.features,
                "action": self.action,
                "residual_base": self.residual_base, "integral_gain": self.integral_gain,
                "integral_band": self.integral_band, "integral_clip": self.integral_clip,
                "integral_windup_decay": self.integral_windup_decay,
                "rules": StopRules(roll_back_after=self.roll_back_after)}


def windup_decay_for(seconds: float) -> WindupDecay | None:
    """The speed integral's windup decay for ``integral_windup_decay`` = ``seconds`` (s; 0: none),
    its time constant the default."""
    return WindupDecay(seconds=seconds) if seconds else None


def check_slow_penalty(penalty: float) -> None:
    """Raise ``ValueError`` unless ``penalty`` (reward per m/s below :data:`SLOW_HIP_SPEED`) is finite and <= 0."""
    if not (np.isfinite(penalty) and penalty <= 0.0):
        raise ValueError(f"slow_penalty must be finite and <= 0, got {penalty}")


def check_residual_base(base: str, action: str, decision_period: int, integral_gain: float) -> None:
    """Raise ``ValueError`` unless ``base`` is one of :data:`RESIDUAL_BASES` and, if not
    ``classic``, the action is a residual decided every N > 0 ticks without a speed integral
    (the recovery controller acts within the step and has no integral)."""
    if base not in RESIDUAL_BASES:
        raise ValueError(f"residual_base must be one of {RESIDUAL_BASES}, got {base!r}")
    if base != "classic":
        if action != "residual":
            raise ValueError(f"residual_base {base} is what a residual adds to: it needs action residual")
        if not decision_period:
            raise ValueError(f"residual_base {base} acts within the step: it needs a decision period > 0 ticks")
        if integral_gain:
            raise ValueError(f"residual_base {base} has no speed integral: integral_gain must be 0")


PRESETS = {
    "shipped": EpisodeConfig(max_steps=500, decision_period=20, distribution="moderate", fall_penalty=-50.0,
                             features="memory", action="residual", integral_gain=0.2),
    "recovery": EpisodeConfig(max_steps=500, decision_period=20, distribution="recovery", fall_penalty=-50.0,
                              alive_bonus=0.05, roll_back_after=0.6, features="body", action="residual",
                              residual_base="recovery"),
}
"""The episodes of the runs we ship and train, by name (``config/train/shipped_es.yaml``, the
shipped policy's; ``config/train/recovery_residual_es.yaml``, the push-recovery residual's;
tested equal), registered as ``RabbitHZD-Shipped-v0`` and ``RabbitHZD-Recovery-v0``
(:func:`make_preset`)."""


def make_preset(preset: str, **overrides) -> "RabbitHZDEnv":
    """The env of :data:`PRESETS` ``[preset]`` (what ``gymnasium.make("RabbitHZD-Shipped-v0")``
    builds), with ``overrides`` of its keyword arguments (e.g. ``render_mode``)."""
    if preset not in PRESETS:
        raise ValueError(f"preset must be one of {sorted(PRESETS)}, got {preset!r}")
    return RabbitHZDEnv(**{**PRESETS[preset].env_kwargs(), **overrides})


class RabbitHZDEnv(gym.Env):
    """See the module docstring."""

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 50}

    def __init__(self, model: ModelOptions | str = "paper", speed_range: tuple[float, float] = (0.7, 1.5),
                 max_steps: int = DEFAULT_MAX_STEPS, window: int = 1000, fall_penalty: float = -10.0,
                 alive_bonus: float = 0.0, slow_penalty: float = 0.0, reward: str = "tracking",
                 rules: StopRules = StopRules(), margin: float = 0.15, decision_period: int = 0,
                 distribution: EpisodeDistribution | str = "paper", render_mode: str | None = None,
                 features: str = "paper", action: str = "direct", integral_gain: float = 0.0,
                 residual_base: str = "classic", integral_band: float = 0.0, integral_clip: float = 0.0,
                 integral_windup_decay: float = 0.0) -> None:
        if isinstance(distribution, str) and distribution not in DISTRIBUTIONS:
            raise ValueError(f"distribution must be one of {sorted(DISTRIBUTIONS)}, got {distribution!r}")
        self.distribution = DISTRIBUTIONS[distribution] if isinstance(distribution, str) else distribution
        decision_period = decision_ticks(decision_period)  # the one check: 0 or N ticks
        if not (isinstance(max_steps, int) and max_steps >= 1):
            raise ValueError(f"max_steps must be a whole number >= 1, got {max_steps!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        self.decision_period = decision_period
        # frames per second of sim time when rendered once per env step (a walking step: ~0.5 s)
        self.metadata = {**self.metadata, "render_fps": round(1000 / decision_period) if decision_period else 2}
        self.render_mode = render_mode
        self._view = None  # the renderer or viewer, opened on first use
        self.library = GaitLibrary.load()
        if action not in ACTIONS:
            raise ValueError(f"action must be one of {ACTIONS}, got {action!r}")
        self.action = action
        check_integral_gain(integral_gain, action)
        direct = ActionBounds.from_library(self.library, margin)
        check_residual_base(residual_base, action, decision_period, integral_gain)
        self.residual = (ResidualAction(self.library, residual_sum_bounds(self.library, residual_base, margin),
                                        integral_gain=integral_gain) if action == "residual" else None)
        self.residual_base = residual_base
        self.base = (rule_base(residual_base, self.library, RecoveryConfig(), decision_period,  # the rule's
                                   DEFAULT_DECISION_WINDOW) if residual_base != "classic" else None)  # as trained
        self._controller = ControllerConfig(**controller_settings(self.base))
        self.bounds = self.residual.bounds if self.residual is not None else direct
        self.action_space = gym.spaces.Box(-1.0, 1.0, (N_FREE + 1,), dtype=np.float32)
        self.features = features
        memory = MemoryConfig.for_features(features, decision_period, integral_gain,  # raises for a bad combination
                                           self.library.speed_range, integral_band or None, integral_clip or None,
                                           windup_decay_for(integral_windup_decay))
        self.memory = SpeedMemory(memory) if memory is not None else None
        low, high = [speed_range[0], -3.0, -3.0], [speed_range[1], 3.0, 3.0]
        if self.memory is not None:
            limit = self.memory.config.integral.limit
            low, high = low + [-limit] + [-1.0] * (N_FREE + 1), high + [limit] + [1.0] * (N_FREE + 1)
            if memory.body:  # pitch, pitch rate, phase, phase rate, hip velocity
                low, high = low + [-1.0, -20.0, 0.0, -20.0, -3.0], high + [1.0, 20.0, 1.0, 20.0, 3.0]
        self.observation_space = gym.spaces.Box(np.array(low, dtype=np.float32), np.array(high, dtype=np.float32),
                                                dtype=np.float32)
        self.speed_range = speed_range
        self.max_steps = max_steps
        self.window_size = window
        self.fall_penalty = fall_penalty
        check_reward(reward, fall_penalty)
        self.reward = reward
        if not (np.isfinite(alive_bonus) and alive_bonus >= 0.0):
            raise ValueError(f"alive_bonus must be finite and >= 0, got {alive_bonus}")
        self.alive_bonus = alive_bonus
        check_slow_penalty(slow_penalty)
        self.slow_penalty = slow_penalty
        self.rules = rules
        self.model_options = ModelOptions(model) if isinstance(model, str) else model
        self._models = {self.model_options: load_model(self.model_options)}
        self._model = self._models[self.model_options]
        self._loop: ClosedLoop | None = None

    @property
    def loop(self) -> ClosedLoop | None:
        """The closed loop of the episode in progress (None before the first reset)."""
        return self._loop

    # ------------------------------------------------------------------ helpers
    def _observation(self, clean: Observation | None = None) -> np.ndarray:
        """The policy's input from the loop's noise-free observation ``clean`` (taken now if None)."""
        if clean is None:
            clean = self._loop.observation(moving=bool(self.decision_period))
        obs = np.array(clean.as_tuple())
        noise = self.distribution.observation_noise
        if noise > 0.0:
            obs[1:] += self.np_random.normal(0.0, noise, 2)
        obs = clip(obs, self.observation_space.low[:3], self.observation_space.high[:3])
        if self.memory is not None:
            obs = self.memory.inputs(obs, self._loop.body_state() if self.memory.config.body else None)
        return clip(obs, self.observation_space.low, self.observation_space.high).astype(np.float32)

    def _run_to_touchdown(self) -> tuple[bool, bool]:
        """Simulate until the next touchdown (or a stop rule); returns (fell, stalled)."""
        loop = self._loop
        loop.run(max_ticks=self._max_ticks, until_touchdown=True)
        return loop.fell, loop.stalled

    def _run_decision(self) -> tuple[bool, bool]:
        """One environment step: to the next touchdown, or N ticks with a decision period."""
        if not self.decision_period:
            return self._run_to_touchdown()
        self._loop.run(max_ticks=self.decision_period)
        return self._loop.fell, self._loop.stalled

    def _speed_option(self, options: dict, key: str, drawn: float) -> float:
        """``options[key]`` (m/s) if given and inside the speed range, else ``drawn``."""
        if key not in options:
            return drawn
        value, (lo, hi) = float(options[key]), self.speed_range
        if not lo <= value <= hi:
            raise ValueError(f"reset option {key} = {value} is outside [{lo}, {hi}] m/s")
        return value

    # ---------------------------------------------------------------- gym API
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        lo, hi = self.speed_range
        options = options or {}
        first, second = (float(self.np_random.uniform(lo, hi)) for _ in range(2))  # drawn even if given
        self._switch_step = int(self.np_random.integers(self.max_steps // 4, 3 * self.max_steps // 4 + 1))
        self.desired_speed = self._speed_option(options, "desired_speed", first)
        self._next_speed = self._speed_option(options, "next_speed", second)
        gait = self.library.nearest(self.desired_speed)
        for _attempt in range(START_ATTEMPTS):  # a model and delay whose first step completes
            scenario = self._draw_scenario()
            self._model = self._models.get(scenario.model) or self._models.setdefault(scenario.model,
                                                                                       load_model(scenario.model))
            self._loop = ClosedLoop(scenario, start=GaitCommand(gait.alpha, gait.kd), start_speed=gait.speed,
                                    kp=gait.kp, model=self._model, observe_speed=True,
                                    decision_period=self.decision_period, controller=self._controller)
            self._max_ticks = int(round((self.rules.stall_after + 1.0) / self._model.opt.timestep))
            fell, stalled = self._run_to_touchdown()  # start observing at a touchdown
            if not (fell or stalled):
                break
        else:
            raise RuntimeError(f"the starting gait at {self.desired_speed:.3f} m/s did not reach its first touchdown "
                               f"in {START_ATTEMPTS} drawn scenarios")
        self._steps = 0
        reset_policy(self.base)
        if self.memory is not None:  # the last action: the gait it starts on (a residual: zero)
            self.memory.reset(None if self.residual is not None
                              else self.bounds.to_normalised(np.append(gait.free, gait.kd)))
        if self.render_mode == "human":
            self.render()
        return self._observation(), {"desired_speed": self.desired_speed, "privileged": self.privileged_state()}

    def privileged_state(self) -> np.ndarray:
        """The episode's state a critic may see (:data:`PRIVILEGED_STATE`, float32)."""
        loop = self._loop
        scenario, sim = loop.scenario, loop.sim
        model = scenario.model
        since = loop.time - (loop.touchdowns[-1].time if loop.touchdowns else loop.start_time)
        return np.array((*loop.body_state(), float(loop.data.qpos[1]), since, sim.push_wrench[0], self._push_impulse,
                         float(self._push_impulse != 0.0 and sim.pushes_started == 0),
                         PACKAGED_FRICTION if model.friction is None else model.friction, model.torso_mass_scale,
                         float(model.variant == "drives"), scenario.torque_delay), dtype=np.float32)

    def _draw_scenario(self) -> Scenario:
        """This episode's scenario: the commands, a push, the model and the delay (drawn
        from ``distribution``; the paper's distribution draws nothing here)."""
        d, rng = self.distribution, self.np_random
        lo, hi = self.speed_range
        horizon = self.max_steps * (self.decision_period / 1000.0 if self.decision_period else 0.6)
        schedule = [(0.0, self.desired_speed)]
        if d.command_interval is not None:
            t, speed = float(rng.uniform(*d.command_interval)), self._next_speed
            while t < horizon:
                schedule.append((t, speed))
                t, speed = t + float(rng.uniform(*d.command_interval)), float(rng.uniform(lo, hi))
        pushes, phase_pushes = (), ()
        self._push_impulse = 0.0
        if d.push_probability > 0.0 and rng.random() < d.push_probability and horizon > 2.0:
            time = float(rng.uniform(1.0, horizon - 1.0))
            if d.relative_impulse:
                direction = -1 if rng.random() < d.backward_fraction else 1
                command = next(v for t, v in reversed(schedule) if t <= time)
                scale = d.backward_scale if direction < 0 else 1.0
                impulse = (direction * scale * float(rng.uniform(d.min_impulse, d.max_impulse))
                           * classic_margin(command, direction))
            elif d.min_impulse > 0.0:
                impulse = float(rng.choice((-1.0, 1.0)) * rng.uniform(d.min_impulse, d.max_impulse))
            else:
                impulse = float(rng.uniform(-d.max_impulse, d.max_impulse))
            if d.push_timing == "phase":
                phase_pushes = (PhasePush(time, float(rng.uniform(0.0, 1.0)), impulse / d.push_duration,
                                          d.push_duration),)
            else:
                pushes = (Push(time, impulse / d.push_duration, d.push_duration),)
            self._push_impulse = impulse
        model = ModelOptions(d.variants[int(rng.integers(len(d.variants)))],
                             friction=d.frictions[int(rng.integers(len(d.frictions)))],
                             torso_mass_scale=d.torso_mass_scales[int(rng.integers(len(d.torso_mass_scales)))])
        if d.variants == ("paper",) and d.frictions == (None,) and d.torso_mass_scales == (1.0,):
            model = self.model_options  # the env's own model (the paper's distribution)
        delay = d.torque_delays[int(rng.integers(len(d.torque_delays)))]
        return Scenario(schedule=tuple(schedule), pushes=pushes, phase_pushes=phase_pushes, model=model, torque_delay=delay, rules=self.rules,
                        window=self.window_size)

    def step(self, action):
        if self._loop is None:
            raise RuntimeError("call reset() before step()")
        if self.memory is not None:
            self.memory.record(clip(np.asarray(action, dtype=float), -1.0, 1.0))
        action = self.bounds.to_physical(action)
        if self.base is not None:  # on the base controller's decision now (it reads the body state)
            base = self.base.act(replace(self._loop.observation(moving=True), body=self._loop.body_state()))
            action = self.residual.compose_on(action * residual_gate(self.base), np.append(reduce_alpha(base.alpha),
                                                                                         base.kd))
        elif self.residual is not None:
            action = self.residual.compose(action, self.desired_speed,
                                           self.memory.integral if self.memory is not None else 0.0)
        try:
            command = GaitCommand(tuple(expand_alpha(action[:N_FREE])), float(action[N_FREE]))
            rejected = not (self._loop.apply_gait(command) if self.decision_period else self._loop.set_gait(command))
        except ValueError:
            rejected = True
        fell, stalled = self._run_decision()
        self._steps += 1
        self.desired_speed = self._loop.desired_speed  # the schedule's command (broad distributions)
        clean = self._loop.observation(moving=bool(self.decision_period))
        obs = self._observation(clean)
        mean_speed = float(clean.mean_speed)  # noise-free
        terminated = fell or stalled
        truncated = not terminated and self._steps >= self.max_steps
        terms = reward_terms(self.reward, self._loop, mean_speed, self.desired_speed, terminated, truncated,
                             self.fall_penalty, self.alive_bonus, self.slow_penalty)
        reward = sum(terms.values())
        info = {"desired_speed": self.desired_speed, "mean_speed": mean_speed, "fell": fell,
                "stalled": stalled, "rejected": rejected, "time": self._loop.time,
                "privileged": self.privileged_state(), **terms}
        if self.distribution.command_interval is None and self._steps == self._switch_step:  # the paper's change
            self.desired_speed = self._next_speed
            self._loop.set_command(self._next_speed)
        if self.render_mode == "human":
            self.render()
        return obs, float(reward), terminated, truncated, info

    def render(self):
        """``rgb_array``: the current state as an RGB frame (240 x 320 x 3, uint8) from a side
        camera following the hip; ``human``: the state shown in MuJoCo's viewer (called by
        reset and step); None without a render mode."""
        if self.render_mode is None:
            gym.logger.warn("render() without a render_mode: give render_mode to gymnasium.make")
            return None
        if self._loop is None:
            raise RuntimeError("call reset() before render()")
        if self.render_mode == "rgb_array":
            from rabbit_sim.rendering import FrameRenderer  # OpenGL only when a frame is asked for

            if self._view is None or self._view.model is not self._loop.model:
                self.close()
                self._view = FrameRenderer(self._loop.model)
            return self._view.render(self._loop.data)
        from rabbit_sim.viewer import PassiveViewer  # a display only when a window is asked for

        if self._view is None or self._view.data is not self._loop.data:  # a new episode: a new loop
            self.close()
            self._view = PassiveViewer(self._loop.model, self._loop.data)
        self._view.sync(force=True)
        return None

    def close(self) -> None:
        if self._view is not None:
            self._view.close()
            self._view = None


EPISODE_SECONDS = 30.0
"""s of sim time: the nominal length of ``RabbitHZD-v0``'s 60 walking steps (0.4-0.7 s each)."""


def decisions_for(seconds: float, decision_period: int) -> int:
    """Env steps of ``decision_period`` ticks (1 ms) that last ``seconds`` s of sim time."""
    return max(1, int(round(seconds * 1000 / decision_period)))


class EpisodeLength(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """One episode length for ``gymnasium.make``: the env's own (``max_steps``, which also
    places the command changes and the push) and its TimeLimit's (``max_episode_steps``), which
    Gymnasium keeps apart (``make`` never gives ``max_episode_steps`` to the env). Registered
    as an additional wrapper of every id, applied after the TimeLimit: ``max_episode_steps``
    alone sets the env's length too, and ``max_steps`` alone the TimeLimit's; given both, both
    stay as given. ``RabbitHZD-v0``'s length (60) counts walking steps: with
    ``decision_period=N`` and neither given, an episode is :data:`EPISODE_SECONDS` of sim time,
    ``30000 / N`` decisions (1500 at N = 20), not 60 decisions (1.2 s)."""

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)
        limit, inner = None, env
        while isinstance(inner, gym.Wrapper):
            if isinstance(inner, gym.wrappers.TimeLimit):
                limit = inner
                break
            inner = inner.env
        unwrapped, spec = env.unwrapped, env.unwrapped.spec
        if limit is None or spec is None:
            return
        registered = gym.registry[spec.id].max_episode_steps
        if "max_steps" in spec.kwargs and limit._max_episode_steps == registered:
            limit._max_episode_steps = unwrapped.max_steps  # max_steps alone: the TimeLimit follows
            limit._cached_spec = None
            self._cached_spec = None
        elif "max_steps" not in spec.kwargs:
            period = int(spec.kwargs.get("decision_period") or 0)
            if spec.id == ENV_ID and period > 0 and limit._max_episode_steps == registered:
                # the id's length is in walking steps: N ms decisions last as long in sim time
                limit._max_episode_steps = decisions_for(EPISODE_SECONDS, period)
                limit._cached_spec = None
                self._cached_spec = None
            unwrapped.max_steps = limit._max_episode_steps  # max_episode_steps alone (or the id's): the env follows


register(gym)  # also here: gymnasium.make("rabbit_policy.learning.env:RabbitHZD-v0") imports this module
