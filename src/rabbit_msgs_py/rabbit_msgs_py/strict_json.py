"""Strict JSON for everything the project prints or writes (ROS-free): non-finite floats
(NaN, infinity) become ``null``, which every JSON parser accepts; Python's default
``json.dumps`` would write the bare ``NaN`` that strict parsers reject."""

from __future__ import annotations

import json
import math
from typing import Any


def finite_or_none(value: Any) -> Any:
    """``value`` with every non-finite float inside it (dicts, lists, tuples) replaced by None."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: finite_or_none(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_or_none(v) for v in value]
    return value


def dumps(value: Any, **kwargs: Any) -> str:
    """``json.dumps`` of :func:`finite_or_none` (``value``), refusing anything else non-finite."""
    return json.dumps(finite_or_none(value), allow_nan=False, **kwargs)
