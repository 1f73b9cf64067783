"""The model-based push-recovery baseline, ``recovery``: classic HZD plus a hand-designed
rule that acts within the step when the hip falls behind where it was a step ago.

Why this rule (docs/learning.md, 2026-11-26 (later), "the ceiling of each action family and a
model-based baseline"): classic HZD's backward failures end in the first stance after the
push. The hip stops short of the stance foot, the phase stalls and the robot rocks back (a
stall, not a fall), and a new gait queued for the next touchdown never lands. The ceiling
study found that gaits applied at once, inside that stance, reach far beyond classic's
margin, and a scan of single directions (a probe at commit fb3c2fc, docs/learning/README.md) found
directions that rescue most pushes at 1.5x classic's margin; a CMA-ES tuning on a push grid
(``scripts/tune_recovery.py``) settled on **swinging the swing leg forward with its knee
straighter, the torso brought back** over the middle of the step (Bezier rows 1-4, so the
step's start and end postures, and the impact equalities, stay as they are).

The rule, every 20 ticks (as classic decides), from the body state (:mod:`.body`):

1. the hip's deficit d = r(tau) - v_x / v_c - ``threshold``: v_x is the hip velocity now
   (m/s, world x), v_c the ramped command (below), r(tau) the slowest of the four previous
   steps at the same phase (:class:`StepMemory`, ``bins`` phase bins), each step's hip
   velocity there over the larger of the ramped command then and now. The reference is
   the robot's own recent steps, so nothing needs calibrating and a model error (friction,
   masses, drives) moves it with the walk. A step in which w (below) reached
   ``forget_weight`` is not kept: a pushed step is not how the robot walks, and kept it
   hid a second push;
2. w = clip(d / ``full``, 0, 1) while the phase is inside the step (0 < tau < 1: at its
   ends the hip phase is clamped and says nothing of the hip's progress), the previous
   steps are known and the command is not ramping down, else 0 (a commanded deceleration
   is not a push).

   Why the larger command: after a deceleration the steps before were fast for their
   (higher) command, so their hip velocity over it keeps the fast steps from looking like
   the norm; after an acceleration the hip is as fast as in the steps before or faster,
   so their hip velocity over today's (higher) command keeps the hip's lag behind the new
   command from looking like a push. The gate holds the rule off only while the command
   ramps down: held off during a ramp up, it missed the stall an acceleration from 0.7 m/s
   to 1.3-1.5 m/s runs into (docs/learning.md, 2026-11-27 (fourth));
3. the gait is classic's with ``w * offsets`` (rad) added to rows 1-4 of the four outputs
   (stance hip, stance knee, swing hip, swing knee), applied at once: no blend, no queue
   (:data:`CONTROLLER_SETTINGS`, which the loops and the stack give the controller).
   Classic's gait is the library's for the command rate-limited to ``command_rate`` m/s per
   decision, the ramp held from ``hold_from`` of phase to the touchdown: applied at once, a
   library gait that jumps with the command, or keeps changing late in the step (moving the
   swing leg's path just before it lands), makes decelerations fall; classic queues such a
   gait for the touchdown for the same reason (``ControllerConfig.within_step_until``). A
   gait for another speed applied at once moves the phase itself, so after a large
   acceleration the ramp can run on for most of a step; the rule of 1-2 catches the stall
   that follows. How the rate and hold were chosen: docs/learning.md.

Undisturbed, w stays 0 and the gait is classic's (the limit cycle is classic's). The rule
never speeds up: a forward push (the hip ahead of its last step) leaves classic alone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rabbit_hzd_controller.alpha import N_FREE, N_OUTPUTS, expand_alpha, reduce_alpha
from rabbit_policy.runtime.alpha_blend import AlphaBlend
from rabbit_policy.runtime.body import touched_down
from rabbit_policy.runtime.classic import RateLimitedPolicy
from rabbit_policy.runtime.gait_command import GaitCommand
from rabbit_policy.runtime.speed_window import Observation

CONTROLLER_SETTINGS = {"within_step_blend": 0.0, "within_step_until": 1.0, "blend_phase": 0.0}
"""The controller settings this controller needs (``ControllerConfig`` fields): a gait
applies from the next tick, within the step, not blended in and never queued."""


@dataclass(frozen=True)
class RecoveryConfig:
    """The rule's constants (see the module docstring).

    offsets: rad added to Bezier rows 1-4 of (stance hip, stance knee, swing hip, swing
        knee) at full deficit (w = 1).
    threshold: the deficit (fraction of v_d) below which nothing is done.
    full: the deficit beyond the threshold (fraction of v_d) at which w reaches 1.
    command_rate: m/s per decision (20 ticks) the base gait's speed follows the command by.
    hold_from: phase from which the base gait is held until the touchdown.
    bins: phase bins of the step memory.
    forget_weight: a step in which the rule's weight reaches this is left out of the step
        memory (:meth:`StepMemory.forget`): a pushed step is not how the robot walks, and
        kept, as the slowest of the four, it hides a second push for four steps. Near-stall
        steps at the slow end stir the rule a little; a low ``forget_weight`` would leave
        them out too and let the memory go stale (docs/learning.md, 2026-11-28 (second)).
    forget_steps: at most this many steps in a row are left out; the next is kept whatever
        its weight (a walk slower than its memory step after step is not pushed step after
        step).
    forget_after: nothing is left out within this many seconds (s) after a change of the
        command (the walk's start is not one): accelerating from the slow end, the rule
        catches the stall it runs into step after step, and those steps are how the robot
        walks while it speeds up; left out, the memory goes stale.
    memory_steps: the steps before the one now that the step memory keeps (its reference is
        the slowest of them at each phase).
    ramp_floor: m/s, the lowest ramped command the hip velocity is divided by (a command
        ramping up from a standstill is not divided by zero).
    """

    offsets: tuple[float, float, float, float] = (-0.11, 0.01, 0.08, -0.23)
    threshold: float = 0.1
    full: float = 0.24
    command_rate: float = 0.04
    hold_from: float = 0.2
    bins: int = 20
    forget_weight: float = 0.9
    forget_steps: int = 2
    forget_after: float = 4.0
    memory_steps: int = 4
    ramp_floor: float = 0.1

    def __post_init__(self) -> None:
        if len(self.offsets) != N_OUTPUTS or not all(np.isfinite(self.offsets)):
            raise ValueError(f"RecoveryConfig.offsets must be {N_OUTPUTS} finite numbers (rad), got {self.offsets!r}")
        if not (np.isfinite(self.threshold) and self.threshold >= 0.0):
            raise ValueError(f"RecoveryConfig.threshold must be finite and >= 0, got {self.threshold}")
        if not (np.isfinite(self.full) and self.full > 0.0):
            raise ValueError(f"RecoveryConfig.full must be finite and > 0, got {self.full}")
        if not (np.isfinite(self.command_rate) and self.command_rate > 0.0):
            raise ValueError(f"RecoveryConfig.command_rate must be finite and > 0 m/s, got {self.command_rate}")
        if not (isinstance(self.bins, int) and self.bins >= 2):
            raise ValueError(f"RecoveryConfig.bins must be a whole number >= 2, got {self.bins!r}")
        if not (np.isfinite(self.forget_weight) and 0.0 < self.forget_weight <= 1.0):
            raise ValueError(f"RecoveryConfig.forget_weight must be a weight in (0, 1], got {self.forget_weight}")
        if not (isinstance(self.forget_steps, int) and self.forget_steps >= 0):
            raise ValueError(f"RecoveryConfig.forget_steps must be a whole number >= 0, got {self.forget_steps!r}")
        if not (np.isfinite(self.forget_after) and self.forget_after >= 0.0):
            raise ValueError(f"RecoveryConfig.forget_after must be finite and >= 0 s, got {self.forget_after}")
        if not (isinstance(self.memory_steps, int) and self.memory_steps >= 1):
            raise ValueError(f"RecoveryConfig.memory_steps must be a whole number >= 1, got {self.memory_steps!r}")
        if not (np.isfinite(self.ramp_floor) and self.ramp_floor > 0.0):
            raise ValueError(f"RecoveryConfig.ramp_floor must be finite and > 0 m/s, got {self.ramp_floor}")


class StepMemory:
    """Per phase bin, the hip velocity (m/s, world x) and the ramped command then (m/s), for
    the step now and the ``depth`` steps before; a touchdown (the phase falling back by more
    than half a step) shifts them. The reference at a phase is the slowest of the steps
    before there, each as its hip velocity over the larger of its command and today's: so a
    walk whose legs alternate (a period-two gait, common at 0.7 m/s and on low friction) is
    not taken for a pushed one, nor is the return to speed after a forward push (the steps
    before the push are slower than those after it), nor a commanded speed change in either
    direction (the module docstring)."""

    def __init__(self, bins: int, depth: int, max_dropped: int) -> None:
        self.bins = bins
        self.depth = depth
        self.max_dropped = max_dropped
        self.reset()

    def reset(self) -> None:
        self.steps = [np.full((self.bins, 2), np.nan) for _ in range(self.depth + 1)]  # now, then the steps before
        self._last_tau: float | None = None
        self._forget = False
        self._dropped = 0  # steps dropped in a row

    def forget(self) -> None:
        """Leave the step now out of the memory: at its touchdown it is dropped, and the
        steps before it stay the reference, unless ``max_dropped`` steps in a row were dropped
        already: a walk slower than its memory step after step is not pushed step after step
        (``RecoveryConfig.forget_weight``, ``forget_steps``)."""
        self._forget = True

    def observe(self, tau: float, hip_velocity: float, command: float) -> float | None:
        """Record the hip velocity (m/s) at phase ``tau`` under the ramped ``command`` (m/s,
        > 0); the reference there: the slowest of the previous steps' hip velocity over the
        larger of their command and ``command`` (each at its bin, or its nearest recorded
        one), None before ``depth`` whole steps are known."""
        if touched_down(self._last_tau, tau):
            if self._forget and self._dropped < self.max_dropped:
                self.steps[0] = np.full((self.bins, 2), np.nan)
                self._dropped += 1
            else:
                self.steps = [np.full((self.bins, 2), np.nan)] + self.steps[:self.depth]
                self._dropped = 0
            self._forget = False
        self._last_tau = tau
        b = min(max(int(tau * self.bins), 0), self.bins - 1)
        self.steps[0][b] = (hip_velocity, command)
        references = []
        for step in self.steps[1:]:
            known = np.flatnonzero(~np.isnan(step[:, 0]))
            if known.size < self.bins // 2:  # not a whole step (the walk's first ones)
                return None
            velocity, then = step[known[np.argmin(np.abs(known - b))]]
            references.append(float(velocity / max(then, command)))
        return min(references)


class RecoveryPolicy:
    """Classic HZD (the library's gait for the ramped command, every 20 ticks) plus the
    recovery rule (the module docstring). ``classic`` is the library policy it adds to;
    ``needs_body``: it reads ``observation.body``; ``controller_settings``: what the
    controller must run with."""

    needs_body = True
    controller_settings = CONTROLLER_SETTINGS
    gates_residual = False  # True: a residual on it is scaled by last_weight (the recovery_gated base)

    def __init__(self, classic, config: RecoveryConfig = RecoveryConfig(), decision_period: int = 20,
                 decision_window: int = 1000) -> None:
        self.classic = classic
        self.config = config
        self._base = RateLimitedPolicy(classic, config.command_rate)
        self.memory = StepMemory(config.bins, config.memory_steps, config.forget_steps)
        self.decision_period = decision_period
        self.decision_window = decision_window
        self.name = f"recovery@{decision_period}ticks"
        self._offsets = np.zeros((5, N_OUTPUTS))
        self._offsets[1:, :] = np.asarray(config.offsets)
        self._held = None  # the base gait held late in the step
        self.last_weight = 0.0
        self._forget_after = int(np.ceil(config.forget_after * 1000.0 / max(decision_period, 1)))  # decisions
        self._last_desired: float | None = None
        self._since_change = self._forget_after  # decisions since the command last changed

    def with_config(self, config: RecoveryConfig) -> "RecoveryPolicy":
        """The same controller with other constants (tuning)."""
        return RecoveryPolicy(self.classic, config, self.decision_period, self.decision_window)

    def reset(self) -> None:
        self._base.reset()
        self.memory.reset()
        self._held = None
        self.last_weight = 0.0
        self._last_desired = None
        self._since_change = self._forget_after

    def start_command(self, speed: float):
        """Classic's gait at ``speed`` (no body state exists before the walk)."""
        return self.classic.act(Observation(speed, speed, 0.0))

    def weight(self, tau: float, fraction: float, reference: float | None) -> float:
        """w in [0, 1]: how much of the offsets apply (the module docstring); ``fraction``:
        the hip velocity over the ramped command now, ``reference`` the previous steps'
        slowest at this phase (:meth:`StepMemory.observe`; None: unknown)."""
        if reference is None or not 0.0 < tau < 1.0:
            return 0.0
        deficit = reference - fraction - self.config.threshold
        return min(max(deficit / self.config.full, 0.0), 1.0)

    def act(self, observation: Observation):
        if observation.body is None:
            raise ValueError("the recovery controller needs the body state (observation.body)")
        _, _, tau, _, hip_velocity = observation.body
        if tau < self.config.hold_from or self._held is None:
            self._held = self._base.act(observation)  # the ramp advances early in the step only
        command = self._held
        ramped = max(self._base.command, self.config.ramp_floor)  # the command the base gait is for (m/s), ramping to v_d
        reference = self.memory.observe(tau, hip_velocity, ramped)
        slowing = self._base.command > observation.desired_speed + 1e-9  # a commanded deceleration
        w = 0.0 if slowing else self.weight(tau, hip_velocity / ramped, reference)
        self.last_weight = w  # the rule's weight at this decision (read by diagnostics and gated residuals)
        if self._last_desired is not None and observation.desired_speed != self._last_desired:
            self._since_change = 0  # a change of the command (the walk's start is not one)
        self._last_desired = observation.desired_speed
        self._since_change += 1
        if w >= self.config.forget_weight and self._since_change > self._forget_after:
            self.memory.forget()  # a pushed step is not the norm
        return self.with_offsets(command, w)

    def with_offsets(self, command, w: float):
        """``command`` (a ``GaitCommand``) with ``w`` (0-1) x the offsets added to Bezier
        rows 1-4; ``command`` itself for w <= 0."""
        if w <= 0.0:
            return command
        free = reduce_alpha(command.alpha).reshape(5, N_OUTPUTS) + w * self._offsets
        return GaitCommand(tuple(float(v) for v in expand_alpha(free.reshape(N_FREE))), command.kd)


@dataclass(frozen=True)
class OverlayConfig:
    """How the recovery rule sits on top of another policy (:class:`RecoveryOverlay`): a
    controller spec's ``overlay`` section, read straight into this class (every field a key).

    fast_gate: the rule is held off while the hip's mean speed over the policy's window
        (its observation, m/s) exceeds the command by more than this fraction of it.
    hold: from this weight on, the gait under the offsets is the policy's last one chosen
        with the rule off (w = 0), not its answer now.
    rise_until: from this phase until the touchdown the rule's weight may fall but not rise
        above its value at the last decision before it (1: no limit): offsets that rise late
        in the step, applied at once, move the swing leg's path just before it lands
        (docs/learning.md, 2026-11-28).
    """

    fast_gate: float = 0.1
    hold: float = 0.5
    rise_until: float = 1.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.fast_gate) and self.fast_gate >= 0.0):
            raise ValueError(f"OverlayConfig.fast_gate must be finite and >= 0 (a fraction), got {self.fast_gate}")
        if not (np.isfinite(self.hold) and 0.0 < self.hold <= 1.0):
            raise ValueError(f"OverlayConfig.hold must be a weight in (0, 1], got {self.hold}")
        if not (np.isfinite(self.rise_until) and 0.0 < self.rise_until <= 1.0):
            raise ValueError(f"OverlayConfig.rise_until must be a phase in (0, 1], got {self.rise_until}")


class RecoveryOverlay:
    """The recovery rule (this module's) on top of another policy's gait: the shipped learned
    controller's ``overlay`` (its spec names every constant).

    Every decision, a recovery controller runs beside the policy on the same observation,
    for its rule's weight w only (its step memory, its ramped command and the deceleration
    gate: the module docstring), and the gait becomes the policy's plus w x the offsets. Two
    differences from the recovery controller:

    * ``fast_gate``: w = 0 while the hip's mean speed exceeds the command by more than that
      fraction: after a forward push the policy's long fast step starts with a hip slower than
      at the same phase of the steps before, which the rule would take for a backward push.
    * ``hold``: once w reaches it, the offsets go onto the policy's last gait chosen with the
      rule off (a network answers a backward push by asking for speed, which works against
      the rule); below ``hold`` the policy keeps deciding.

    ``at_once``: the controller applies every gait at once (:data:`CONTROLLER_SETTINGS`, as the
    recovery controller; else it blends them in with its defaults, as the network was trained);
    ``blend``: with ``at_once``, the overlay blends the policy's own gaits in itself
    (:class:`~.alpha_blend.AlphaBlend`, as the controller's defaults would), so that only the
    offsets act at once; ``rise_until``: w does not rise from that phase of the step on.
    Undisturbed, w stays 0 and the walk is the policy's own. What each choice measured: docs/learning.md, "2026-11-27 (eighth)" and
    "2026-11-28"; the shipped controller's figures: docs/results.md."""

    def __init__(self, config: OverlayConfig, decision_period: int, rule: "RecoveryPolicy",
                 blend: AlphaBlend | None = None, at_once: bool = False) -> None:
        """``rule``: the recovery controller whose weight is used; ``blend``: the policy's gaits
        blended in by the overlay (None: not). A controller spec gives every one
        (:func:`rabbit_policy.spec.build`: ``at_once`` from its controller section)."""
        if decision_period < 1:
            raise ValueError("the recovery overlay acts within the step: its policy must decide every N >= 1 ticks")
        if blend is not None and not at_once:
            raise ValueError("the overlay blends the policy's gaits only when the controller applies them at once "
                             "(else the controller would blend them again)")
        self.config = config
        self.controller_settings = dict(CONTROLLER_SETTINGS) if at_once else {}
        self.rule = rule
        self._blend = blend  # the policy's gaits blended in (None: not)
        self._held = None
        self._cap: float | None = None  # rise_until: the weight w may not rise above until the touchdown
        self.last_weight = 0.0

    def reset(self) -> None:
        self.rule.reset()
        self._held = None
        if self._blend is not None:
            self._blend.reset()
        self._cap = None
        self.last_weight = 0.0

    def start(self, command) -> None:
        """The gait the walk starts on (a blend starts from it)."""
        if self._blend is not None:
            self._blend.start(command.alpha, command.kd)

    def blended(self, observation: Observation, command):
        """With a blend: the policy's gait for the next decision period, as the controller's
        defaults would bring it in (:class:`~.alpha_blend.AlphaBlend`: blended over 0.2 of
        phase, its rate kept when a new gait restarts the blend; from 0.6 of phase queued for
        the touchdown, its Kd too)."""
        _, _, tau, tau_rate, _ = observation.body
        alpha, kd = self._blend.step(tau, tau_rate, command.alpha, command.kd)
        return GaitCommand(tuple(float(v) for v in alpha), kd)

    def apply(self, observation: Observation, command):
        """The gait for this decision: ``command`` (the policy's, a ``GaitCommand``) with the
        rule on it (needs ``observation.body``)."""
        if self._blend is not None:
            command = self.blended(observation, command)
        self.rule.act(observation)
        w = self.rule.last_weight
        if self.config.fast_gate > 0.0 and observation.mean_speed > observation.desired_speed * (1.0 + self.config.fast_gate):
            w = 0.0
        if observation.body[2] >= self.config.rise_until:
            if self._cap is None:
                self._cap = self.last_weight  # w at the last decision before rise_until
            w = min(w, self._cap)
        else:
            self._cap = None
        self.last_weight = w
        if w <= 0.0:
            self._held = command
            return command
        if w >= self.config.hold and self._held is not None:
            command = self._held
        return self.rule.with_offsets(command, w)
