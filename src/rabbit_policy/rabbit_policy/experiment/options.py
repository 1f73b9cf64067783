"""The model-error options of a walk, one definition for ``scripts/walk.py`` (the fast path)
and ``scripts/run_stack.py`` (the node stack, as ``sim_node`` parameters): the model variant,
the foot friction, the torso mass and the torque delay."""

from __future__ import annotations

import argparse

from rabbit_msgs_py.cli import non_negative, positive
from rabbit_sim.model import MODEL_VARIANTS, ModelOptions


def add_model_options(parser: argparse.ArgumentParser) -> None:
    """``--model``, ``--friction``, ``--torso-mass-scale``, ``--torque-delay``."""
    parser.add_argument("--model", choices=MODEL_VARIANTS, default="paper",
                        help="model variant: paper (ideal joints) or drives (RABBIT's gears and joint friction)")
    parser.add_argument("--friction", type=positive, default=None, help="foot friction coefficient (default 0.8)")
    parser.add_argument("--torso-mass-scale", type=positive, default=1.0, help="factor on the torso mass and inertia")
    parser.add_argument("--torque-delay", type=non_negative, default=0.0, help="torque delay (s, whole ms)")


def model_options(args: argparse.Namespace) -> ModelOptions:
    """The model of :func:`add_model_options`' arguments."""
    return ModelOptions(args.model, args.friction, args.torso_mass_scale)
