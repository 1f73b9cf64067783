"""Test-session environment: every ROS process in the tests discovers on localhost only and
uses a domain ID of its own, so concurrent runs do not cross-talk."""

import os
import random

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
if not os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE"):
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", str(random.SystemRandom().randint(1, 101)))
