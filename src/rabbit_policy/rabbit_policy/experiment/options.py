"""Options shared by ``scripts/walk.py`` (the fast path) and ``scripts/run_stack.py`` (the
node stack), one definition each: the walk (controller, speed or schedule, duration, pushes),
the model errors (the model variant, the foot friction,
the torso mass and the torque delay; sim_node parameters in the stack) and the policy
(library mode, gait directory, policy file, decision timing, speed integral; policy_node
parameters in the stack)."""

from __future__ import annotations

import argparse

from rabbit_msgs_py.cli import non_negative, positive
from rabbit_msgs_py.decision_ticks import OWN, DecisionTiming, decision_ticks
from rabbit_policy.experiment.scenario import parse_schedule
from rabbit_policy.runtime.speed_command import clamp_schedule
from rabbit_policy.runtime.policies import controller_argument, controller_name
from rabbit_policy.runtime.speed_integral import SPEED_INTEGRAL_HELP
from rabbit_policy.spec.make import spec_kind
from rabbit_sim.physics.model import MODEL_VARIANTS, ModelOptions


def add_walk_options(parser: argparse.ArgumentParser) -> None:
    """``--controller`` or ``--spec``, ``--speed`` or ``--speed-schedule``, ``--duration``,
    ``--push`` (:func:`resolve_controller` settles the controller after parsing)."""
    parser.add_argument("--controller", type=controller_argument, default=None, metavar="{classic,learned,recovery}",
                        help="classic (the default): the HZD gait library; learned: the HZD-RL policy; recovery: "
                             "classic plus the model-based push-recovery rule")
    parser.add_argument("--spec", default="", metavar="FILE",
                        help="a controller spec of any kind (classic, recovery or learned; docs/controller_spec.md), "
                             "edited or written by reproduce.py: the controller is the file's kind")
    command = parser.add_mutually_exclusive_group()
    command.add_argument("--speed", type=positive, default=1.0, help="constant commanded speed (m/s)")
    command.add_argument("--speed-schedule", "--schedule", default=None, metavar="T:V,...",
                         help='speed changes at sim times, "0:0.8,8:1.2" (s:m/s; at least 0.1 s apart)')
    parser.add_argument("--duration", type=positive, default=20.0, help="simulated time (s)")
    parser.add_argument("--push", default="", metavar="T:FX:DUR,...",
                        help='pushes on the torso, "3:-100:0.1" (s, N, s)')


def add_model_option(parser: argparse.ArgumentParser) -> None:
    """``--model``: the model variant (every command that walks the robot)."""
    parser.add_argument("--model", choices=MODEL_VARIANTS, default="paper",
                        help="model variant: paper (ideal joints) or drives (RABBIT's gears and joint friction)")


def add_gait_dir_option(parser: argparse.ArgumentParser) -> None:
    """``--gait-dir``: a classic gait library's directory ("" : the packaged one)."""
    parser.add_argument("--gait-dir", default="", help="classic: gait library directory (default: packaged)")


def add_policy_file_option(parser: argparse.ArgumentParser) -> None:
    """``--policy-file``: the learned controller's spec or checkpoint ("": the packaged spec)."""
    parser.add_argument("--policy-file", default="", help="learned: a controller spec (.yaml, docs/controller_spec.md) "
                                                          "or a training checkpoint (.pt) (default: the packaged spec)")


def add_allow_dirty_option(parser: argparse.ArgumentParser) -> None:
    """``--allow-dirty``: ship from a checkout with uncommitted changes (recorded with the diff's hash)."""
    parser.add_argument("--allow-dirty", action="store_true",
                        help="write what ships although the checkout has uncommitted changes (the provenance then "
                             "records the hash of git diff HEAD); without it such a checkout is refused")


def add_model_options(parser: argparse.ArgumentParser) -> None:
    """``--model``, ``--friction``, ``--torso-mass-scale``, ``--torque-delay``."""
    add_model_option(parser)
    parser.add_argument("--friction", type=positive, default=None, help="foot friction coefficient (default 0.8)")
    parser.add_argument("--torso-mass-scale", type=positive, default=1.0, help="factor on the torso mass and inertia")
    parser.add_argument("--torque-delay", type=non_negative, default=0.0, help="torque delay (s, whole ms)")


def model_options(args: argparse.Namespace) -> ModelOptions:
    """The model of :func:`add_model_options`' arguments."""
    return ModelOptions(args.model, args.friction, args.torso_mass_scale)


def decision_timing(text: str) -> DecisionTiming:
    """An argparse type: ``own``, ``step`` or N ticks (:meth:`DecisionTiming.parse`)."""
    try:
        return DecisionTiming.parse(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def decision_ticks_option(text: str) -> int:
    """An argparse type: ``step`` or N ticks as a training environment takes them (0 or N:
    an environment has no timing of its own, so not ``own``)."""
    try:
        return decision_ticks(DecisionTiming.parse(text).ticks)  # own: ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"a training environment decides at step (0) or every N >= 1 ticks (it has "
                                         f"no timing of its own), got {text!r}") from None


def add_policy_options(parser: argparse.ArgumentParser) -> None:
    """``--library-mode``, ``--gait-dir``, ``--policy-file``, ``--decision-period``,
    ``--speed-integral`` (``make_policy``'s arguments; run_stack hands them to policy_node)."""
    parser.add_argument("--library-mode", choices=("nearest", "interpolate"), default="interpolate",
                        help="classic: the nearest gait or the blend of the two around the command")
    add_gait_dir_option(parser)
    add_policy_file_option(parser)
    parser.add_argument("--decision-period", type=decision_timing, default=OWN, metavar="own|step|TICKS",
                        help="when the policy decides: own = as it was made (classic every 20 ticks, learned as "
                             "trained; the default), step = once per step, N = every N ticks (1 ms), each gait "
                             "applied at once, blended in (-1 and 0 are accepted for own and step)")
    parser.add_argument("--speed-integral", type=non_negative, default=0.0, metavar="KI", help=SPEED_INTEGRAL_HELP)


def resolve_controller(args: argparse.Namespace) -> None:
    """Settle ``args.controller`` (its canonical name) and ``args.policy_file`` after parsing:
    ``--spec FILE`` is the controller its file says (``--controller`` may name the same kind,
    ``--policy-file`` may not be given too); without it ``--controller`` or classic.
    ``ValueError`` / ``PolicyUnavailable`` with one line otherwise."""
    named = controller_name(args.controller) if args.controller else None
    if not args.spec:
        args.controller = named or "classic"
        return
    if args.policy_file:
        raise ValueError("--spec and --policy-file both name the controller's file: give one")
    kind = spec_kind(args.spec)
    if named is not None and named != kind:
        raise ValueError(f"--spec {args.spec} is a {kind} controller, not {named}: leave --controller out")
    args.controller, args.policy_file = kind, args.spec


def schedule_from_args(args: argparse.Namespace) -> tuple[tuple[float, float], ...]:
    """The speed schedule of ``--speed`` / ``--speed-schedule``: parsed, each speed outside
    the controllers' range clamped into it with one ``warning:`` line on stderr (the rule
    policy_node applies to ``/cmd_speed``: ``rabbit_policy.runtime.speed_command``);
    ``ValueError`` for a schedule that is not one."""
    import sys

    schedule = parse_schedule(args.speed_schedule) if args.speed_schedule else ((0.0, args.speed),)
    schedule, lines = clamp_schedule(schedule)
    for line in lines:
        print(f"warning: {line}", file=sys.stderr)
    return schedule


def add_classic_integral_option(parser: argparse.ArgumentParser) -> None:
    """``--classic-integral KI [KI ...]``: the comparisons' extra columns (screen, compare, ship),
    classic HZD with Westervelt's event-based speed integral of each gain (1/s, >= 0), a list
    (empty by default)."""
    parser.add_argument("--classic-integral", nargs="+", type=non_negative, default=[], metavar="KI",
                        help="also classic HZD with the event-based speed integral of this gain (1/s), one column "
                             "each (the base of a residual trained with --integral-gain KI)")
