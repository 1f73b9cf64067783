"""Test-session environment: every ROS process in the tests discovers on localhost only
(ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST unless set) and uses a domain ID of its own, so
concurrent runs do not cross-talk."""

import os
import random

from rabbit_msgs_py.environment import ensure_localhost_discovery

ensure_localhost_discovery()
os.environ.setdefault("ROS_DOMAIN_ID", str(random.SystemRandom().randint(1, 101)))
