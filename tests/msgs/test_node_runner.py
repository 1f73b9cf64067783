"""rabbit_msgs_py.node_runner.run_node, the body of every node process's ``main()``: the signal
handlers it found come back only once the run's rclpy objects are freed. A handler that
raises (quiet_start's, before run_node takes over), run while a C++ destructor of rclpy calls
back into Python, aborted node processes killed with their run_stack ("terminate called after
throwing an instance of 'pybind11::error_already_set' / SystemExit: 143"); here the restore
itself is watched, so no signal has to land in that window by chance."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

pytestmark = pytest.mark.ros  # (a node process)

WATCHED_RUN = '''
import json, signal, weakref
import rclpy.node
from std_msgs.msg import Bool
from rabbit_msgs_py import node_runner

def found(*_):
    raise SystemExit(3)

alive_at_restore = []
built = []  # weak references to the run's rclpy objects
real_signal = signal.signal

def watching(sig, handler):
    if handler is found:  # run_node puts the handler it found back
        alive_at_restore.append(sum(ref() is not None for ref in built))
    return real_signal(sig, handler)

class Probe(rclpy.node.Node):
    def __init__(self, context):
        super().__init__("run_node_probe", context=context)
        self.publisher = self.create_publisher(Bool, "run_node_probe", 10)  # QoS event handlers in C++
        self.subscription = self.create_subscription(Bool, "run_node_probe", lambda _m: None, 10)
        self.done = True  # run_node spins no more: it closes the node at once
        built.extend(weakref.ref(o) for o in (self, self.publisher, self.subscription,
                                              *self.publisher.event_handlers, *self.subscription.event_handlers))

real_signal(signal.SIGTERM, found)
real_signal(signal.SIGINT, found)
signal.signal = watching
status = node_runner.run_node(Probe)
print(json.dumps({"status": status, "alive_at_restore": alive_at_restore,
                  "restored": signal.getsignal(signal.SIGTERM) is found, "built": len(built)}))
'''


def test_run_node_restores_the_handlers_it_found_only_after_the_node_is_freed():
    done = subprocess.run([sys.executable, "-c", WATCHED_RUN], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert report["status"] == 0 and report["restored"] and report["built"] >= 3
    assert report["alive_at_restore"] == [0, 0], report  # SIGINT's and SIGTERM's restore: no node, no event handler
