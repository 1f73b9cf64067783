"""Gait policies for RABBIT: the classic HZD gait library and its optimizer, and the
learned HZD-RL policy."""

from .env import register as _register_env

_register_env()
