"""A real trained checkpoint for the tests of the checkpoint path (``checkpoint_policy``,
``ship_policy.py``, the spec converter): the learned network shipped until 2026-11-29 (ES,
255 generations, memory features, a residual on classic HZD with the speed integral), with the
model card and evaluation ``ship_policy.py`` wrote for it. It left the package when the
shipped network became what ``reproduce.py --preset shipped`` produces (docs/learning.md,
2026-11-29 (second))."""

from __future__ import annotations

from pathlib import Path

SHIPPED_BEFORE = Path(__file__).resolve().parent / "data" / "ship_policy_2026_11_28" / "hzd_rl_policy.pt"
"""The checkpoint; its ``MODEL_CARD.md`` and ``evaluation.json`` beside it."""
