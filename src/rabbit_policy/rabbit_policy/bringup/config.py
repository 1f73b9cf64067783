"""What a run of the stack is: :class:`StackConfig` (one run, as ``scripts/run_stack.py``'s
options give it) and the node parameters and command lines it makes."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

from rabbit_msgs_py.decision_ticks import OWN, DecisionTiming
from rabbit_msgs_py.pairing import new_key

from rabbit_policy.experiment.scenario import (Push, Scenario, format_pushes, format_schedule, on_tick_grid,
                                               validate_schedule)
from rabbit_policy.runtime.policies import PolicyUnavailable, controller_name
from rabbit_policy.spec.make import make_policy
from rabbit_sim.physics.model import ModelOptions
from rabbit_sim.physics.simulation import StopRules


NODE_MODULES = {
    "policy_node": "rabbit_policy.policy_node",
    "hzd_controller_node": "rabbit_hzd_controller.hzd_controller_node",
    "sim_node": "rabbit_sim.sim_node",
    "recorder_node": "rabbit_sim.recorder_node",
}
LAYOUTS = ("composed", "separate", "in-process", "attach")
"""Where the nodes run: ``composed`` (simulator, controller and supervisor in run_stack's
process, on one executor; the policy and a recorder processes of their own), ``separate``
(every node its own process), ``in-process`` (every node in run_stack's process) or
``attach`` (started by hand, not by this run: only the supervisor is run_stack's)."""
COMPOSED_NODES = ("hzd_controller_node", "sim_node")
"""The nodes the ``composed`` layout runs in run_stack's process: the 1 kHz loop."""


@dataclass(frozen=True)
class StackConfig:
    """One run of the stack. ``schedule``: (start time s, speed m/s) pairs, first at 0.
    ``decision``: when the policy decides (:class:`~rabbit_msgs_py.decision_ticks.DecisionTiming`:
    its own timing, once per step, or every N ticks, the controller applying each gait at
    once, told so on ``/hzd/gait_timing``). ``markers_rate``: ``/rabbit/markers`` per s of
    sim time (0 = off); ``viewer``: sim_node opens MuJoCo's viewer."""

    duration: float
    schedule: tuple[tuple[float, float], ...]
    controller: str = "classic"
    mode: str = "lockstep"
    rtf: float = 1.0
    model: str = "paper"
    friction: float = 0.0  # foot friction coefficient (0 = the model's own 0.8)
    torso_mass_scale: float = 1.0  # factor on the torso's mass and inertia
    torque_delay: float = 0.0  # s, whole ms: each torque reply applied that much later (sim_node)
    library_mode: str = "interpolate"
    gait_dir: str = ""
    policy_file: str = ""
    decision: DecisionTiming = OWN
    speed_integral: float = 0.0  # 1/s, classic only: Westervelt's event-based speed integral (0 = off)
    pushes: tuple[Push, ...] = ()
    push_duration: float = 0.1
    stats_file: str = ""
    record: str = ""
    record_compression: str = "none"
    record_overwrite: bool = False
    record_stats_file: str = ""
    controller_stats_file: str = ""  # where hzd_controller_node writes its counts on close ('' = not)
    markers_rate: float = 30.0
    reference_rate: float = 0.0  # /hzd/reference and /hzd/tracking_error per s of sim time (0 = off)
    viewer: bool = False
    recorder_timeout: float = 10.0  # s (wall): a recorder that made no progress this long fails the run
    rules: StopRules = StopRules()  # the fall and stall rules of every experiment
    layout: str = "composed"  # LAYOUTS: where the nodes run
    namespace: str = ""  # every node's ROS namespace ("" = the root); two stacks in two namespaces run side by side
    pairing_key: str = field(default_factory=new_key, repr=False)  # every node: rabbit_msgs_py.pairing

    def __post_init__(self) -> None:
        if not self.duration > 0.0:
            raise ValueError("duration must be > 0 s")
        object.__setattr__(self, "namespace", valid_namespace(self.namespace))
        if self.layout not in LAYOUTS:
            raise ValueError(f"layout must be one of {', '.join(LAYOUTS)}, got {self.layout!r}")
        object.__setattr__(self, "controller", controller_name(self.controller))
        validate_schedule(self.schedule)
        self.scenario()  # raises for a bad model option or torque delay, before any node starts
        if self.rules.roll_back_after:
            raise ValueError("rules.roll_back_after is the training env's early stall rule (the closed loop's); the "
                             "stack's supervisor declares a stall after rules.stall_after s without a touchdown only")
        if not (math.isfinite(self.recorder_timeout) and self.recorder_timeout > 0.0):
            raise ValueError(f"recorder_timeout must be a finite number > 0 s, got {self.recorder_timeout}")
        if not (math.isfinite(self.rtf) and self.rtf > 0.0):
            raise ValueError(f"rtf must be a finite number > 0, got {self.rtf}")
        if not isinstance(self.decision, DecisionTiming):
            raise ValueError(f"decision must be a DecisionTiming, got {self.decision!r}")

    def scenario(self) -> Scenario:
        """The run as a fast-path scenario (the report's; walk.py runs the same one)."""
        return Scenario(schedule=self.schedule, pushes=self.pushes,
                        model=ModelOptions(self.model, self.friction or None, self.torso_mass_scale),
                        torque_delay=self.torque_delay, rules=self.rules)

    def build_policy(self):
        """The policy policy_node builds for this run (run_stack builds it once, to refuse a
        bad one with one line before any node starts and to name it in the report); raises
        ``PolicyUnavailable`` or ``ValueError``."""
        return make_policy(self.controller, self.gait_dir or None, self.library_mode, self.policy_file or None,
                           decision=self.decision, speed_integral=self.speed_integral)

    def node_parameters(self) -> dict[str, dict[str, object]]:
        """The ROS parameters of each node for this run (the recorder only if recording).
        ``solo_check`` 0: run_stack looked for another stack before it starts any node."""
        params: dict[str, dict[str, object]] = {
            "policy_node": {
                "policy": self.controller,
                "library_mode": self.library_mode,
                "gait_dir": self.gait_dir,
                "policy_file": self.policy_file,
                "initial_speed": self.schedule[0][1],
                "decision_period": self.decision.param,
                "speed_integral": self.speed_integral,
                "speed_schedule": format_schedule(self.schedule[1:]),
                "pairing_key": self.pairing_key,
                "solo_check": 0.0,
            },
            # lockstep/paced: the reply to a state the policy decides on waits for that decision
            "hzd_controller_node": {"decision_sync": self.mode != "realtime", "reference_rate": self.reference_rate,
                                    "pairing_key": self.pairing_key, "solo_check": 0.0,
                                    "stats_file": self.controller_stats_file},
            "sim_node": {
                "model": self.model,
                "friction": self.friction,
                "torso_mass_scale": self.torso_mass_scale,
                "torque_delay": self.torque_delay,
                "mode": self.mode,
                "rtf": self.rtf,
                "stop_time": on_tick_grid(self.duration),
                "push_duration": self.push_duration,
                "push_schedule": format_pushes(self.pushes),
                "start_paused": True,
                "wait_for_recorder": bool(self.record) and self.mode in ("lockstep", "paced"),
                "stats_file": self.stats_file,
                "markers_rate": self.markers_rate,
                "viewer": self.viewer,
                "pairing_key": self.pairing_key,
                "solo_check": 0.0,
            },
        }
        if self.record:
            params["recorder_node"] = {
                "output": self.record,
                "compression": self.record_compression,
                "overwrite": self.record_overwrite,
                "stats_file": self.record_stats_file,
            }
        return params


NAMESPACE = re.compile(r"^(/[A-Za-z][A-Za-z0-9_]*)+$")


def valid_namespace(namespace: str) -> str:
    """``"rabbit2"`` or ``"/rabbit2"`` -> ``"/rabbit2"``; ``""`` or ``"/"`` -> ``""`` (the root);
    anything that is not a ROS namespace raises ValueError."""
    if namespace in ("", "/"):
        return ""
    full = namespace if namespace.startswith("/") else "/" + namespace
    if not NAMESPACE.match(full):
        raise ValueError(f"namespace {namespace!r} is not a ROS namespace (letters, digits and _, each part "
                         "starting with a letter, parts separated by /)")
    return full


def ros_arguments(parameters: dict[str, object], namespace: str = "") -> list[str]:
    """``{"mode": "lockstep", "stop_time": 5.0}`` ->
    ``["--ros-args", "-p", "mode:=lockstep", "-p", "stop_time:=5.0"]``; empty strings are
    left out (the node's default applies); a ``namespace`` adds ``-r __ns:=NAMESPACE``."""
    args = ["--ros-args"] + (["-r", f"__ns:={namespace}"] if namespace else [])
    for name, value in parameters.items():
        if value == "":
            continue
        text = str(value).lower() if isinstance(value, bool) else repr(value) if isinstance(value, float) else str(value)
        args += ["-p", f"{name}:={text}"]
    return args


def policy_name(config: StackConfig) -> str | None:
    """The name of the policy policy_node runs for ``config`` (as the fast path names it);
    None if it cannot be built here (policy_node then said why)."""
    try:
        return config.build_policy().name
    except (PolicyUnavailable, ValueError, OSError):
        return None
