"""Process environment defaults for every rabbit-hzd entry point (ROS-free).

Fast DDS multicasts discovery traffic out of the network interface unless discovery is
restricted to this host; every node, script and test therefore runs with
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` unless the user chose otherwise.
"""

from __future__ import annotations

import os
from typing import MutableMapping

DISCOVERY_VARIABLE = "ROS_AUTOMATIC_DISCOVERY_RANGE"


def ensure_localhost_discovery(env: MutableMapping[str, str] | None = None) -> str:
    """Set ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` in ``env`` (default ``os.environ``)
    if it is unset or empty; return the value in force. Call before importing rclpy."""
    env = os.environ if env is None else env
    if not env.get(DISCOVERY_VARIABLE):
        env[DISCOVERY_VARIABLE] = "LOCALHOST"
    return env[DISCOVERY_VARIABLE]
