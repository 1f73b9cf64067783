"""``rabbit_msgs_py.log_lines``: a core's log lines, throttled by key, each severity on its own
call site (rclpy caches a call site's severity: one call for all raised ``ValueError``)."""

from __future__ import annotations

import pytest
import rclpy
from rclpy.context import Context
from rclpy.node import Node

from rabbit_msgs_py.log_lines import LineLogger, LogLine

pytestmark = pytest.mark.ros


def test_lines_of_every_severity_go_through_a_real_node_logger_and_throttle_by_key(capfd):
    context = Context()
    rclpy.init(context=context)
    node = Node("log_lines_test", context=context)
    try:
        log = LineLogger(node.get_logger())
        for line in (LogLine("info", "first info"), LogLine("warning", "a warning"), LogLine("error", "an error"),
                     LogLine("info", "second info")):
            log(line)  # alternating severities: no "Logger severity cannot be changed between calls"
        for k in range(3):
            log(LogLine("error", f"throttled {k}", throttle=60.0, key="burst"))
        log(LogLine("error", "another key", throttle=60.0, key="other"))
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)
    err = capfd.readouterr().err
    for text in ("first info", "a warning", "an error", "second info", "throttled 0", "another key"):
        assert text in err
    assert "throttled 1" not in err and "throttled 2" not in err
