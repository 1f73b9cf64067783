"""Log lines a ROS-free core returns for its node to log (:class:`LogLine`), and the node's side
(:class:`LineLogger`): lines throttled by their key, each severity through its own call site.

rclpy throttles per call site and caches a call site's severity, so a node that logs its core's
lines through one call would throttle them all together and could not change severity between
them; :class:`LineLogger` keeps both apart."""

from __future__ import annotations

import time
from dataclasses import dataclass


@dataclass(frozen=True)
class LogLine:
    level: str  # "info", "warning" or "error"
    text: str
    throttle: float = 0.0  # s (wall): at most one line of this ``key`` this often
    key: str = ""


class LineLogger:
    """Logs :class:`LogLine` s on ``logger`` (an rclpy logger, or anything with ``info``,
    ``warning`` and ``error``)."""

    def __init__(self, logger) -> None:
        self._logger = logger
        self._logged: dict[str, float] = {}  # key -> when a line of it was last logged (monotonic s)

    def __call__(self, line: LogLine) -> None:
        if line.throttle:
            now = time.monotonic()
            if line.key in self._logged and now - self._logged[line.key] < line.throttle:
                return
            self._logged[line.key] = now
        if line.level == "error":
            self._logger.error(line.text)
        elif line.level == "warning":
            self._logger.warning(line.text)
        else:
            self._logger.info(line.text)
