"""sim_node's settings, ROS-free: :class:`SimSettings` (one field per node parameter, its
help the parameter's description) and the modes."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from rabbit_msgs_py import topics
from rabbit_msgs_py.cli import option
from rabbit_msgs_py.pairing import KEY_FILE_HELP, NO_KEY, PairingKey
from rabbit_msgs_py.solo import SOLO_CHECK_HELP
from rabbit_msgs_py.pushes import Push, parse_pushes

from ..physics.model import MODEL_VARIANTS, ModelOptions

TIMESTEP = 0.001
"""s: the model's timestep, one control tick."""

MODES = topics.SIM_MODES


@dataclass(frozen=True)
class SimSettings:
    """sim_node's parameters, one field each, its help the parameter's description (the one
    table :data:`SIM_PARAMS` is made from; ``ros2 param describe`` shows it). Units: s of sim
    time unless said wall, N, N m s/rad."""

    model: str = option("paper", "model variant: paper (ideal joints) or drives (RABBIT's gears and joint friction)",
                        choices=MODEL_VARIANTS)
    friction: float = option(0.0, "foot-ground sliding friction coefficient, > 0 (0 = the model's own, 0.8)",
                             range=(0.0, 10.0))
    torso_mass_scale: float = option(1.0, "factor on the torso's mass and inertia, > 0 (1 = the paper's 12 kg)",
                                     range=(0.001, 10.0))
    torque_delay: float = option(0.0, "apply each torque reply this many s of sim time later, whole ms, >= 0 (until "
                                      "then the first reply), as walk.py --torque-delay", range=(0.0, 1.0), step=0.001)
    mode: str = option("lockstep", "lockstep (one state, one torque reply; deterministic, as fast as it goes), "
                                   "paced (lockstep held to the wall clock times rtf) or realtime (free-running "
                                   "1 kHz wall clock)", choices=MODES)
    rtf: float = option(1.0, "paced: target real-time factor, sim s per wall s, > 0 (slower if the machine cannot "
                             "keep up)", range=(0.001, 1000.0))
    push_duration: float = option(0.1, "how long a /push wrench is held, s of sim time, > 0 (may change at run time)",
                                  range=(0.001, 10.0))
    push_schedule: str = option("", "pushes the simulator applies itself at exact sim times, again after a reset, "
                                    "'T:FX:DUR,...' (s, N, s); '' = none")
    max_push_force: float = option(2000.0, "larger push components are rejected, N, > 0", range=(0.001, 1.0e5))
    stop_time: float = option(0.0, "halt the physics at this sim time, s, >= 0 (0 = never)", range=(0.0, 1.0e9))
    resend_timeout: float = option(0.2, "lockstep: wall s without a torque before the state is re-sent, > 0",
                                   range=(0.001, 60.0))
    watchdog_timeout: float = option(0.008, "realtime: wall s without a torque before damping takes over, > 0 "
                                            "(the gaits go unstable at about 10 ms of torque delay)", range=(0.001, 10.0))
    damping: float = option(20.0, "realtime watchdog damping gain, N m s/rad, >= 0", range=(0.0, 1.0e4))
    max_late_fraction: float = option(0.5, "realtime: halt the physics when more than this share of a second's "
                                           "ticks ran on a stale torque, in (0, 1]", range=(0.001, 1.0))
    start_paused: bool = option(False, "start with the physics paused (/sim/pause false runs it; run_stack starts "
                                       "the run so once every node is connected)")
    wait_for_recorder: bool = option(False, "lockstep/paced: step only while the recorder (/recorder/recorded_until) "
                                            "is at most a few states behind, so a recording loses nothing under any "
                                            "load (run_stack sets it when recording)")
    pairing_key: str = option("", "apply torques only from a controller that signs its replies with this key (16-64 "
                                  "characters; run_stack makes one per stack and gives it to the controller too; read "
                                  "once at start, then removed so ros2 param get cannot read it). '' = the user's own "
                                  "key, $ROS_HOME/rabbit_hzd/pairing_key (made on first use, owner-only); 'none' = no "
                                  "key, UNSAFE: the first controller to answer, until /sim/release_controller, and "
                                  "any node that copies its id", secret=True)
    pairing_key_file: str = option("", KEY_FILE_HELP)
    solo_check: float = option(0.0, SOLO_CHECK_HELP.format(kind="simulator"), range=(0.0, 60.0))
    stats_file: str = option("", "write the run statistics as JSON here when the node closes ('' = don't)")
    markers_rate: float = option(30.0, "/rabbit/markers (RViz/Foxglove 3D view) per s of sim time, >= 0 (0 = off); "
                                       "one also goes out whenever RABBIT is placed", range=(0.0, 1000.0))
    clock_rate: float = option(100.0, "/clock per s of sim time, in (0, 1000] (1000 = every state; rounded to whole "
                                      "ticks), published only while anyone subscribes (use_sim_time nodes)",
                               range=(0.001, 1000.0))
    batch_ticks: int = option(20, "/sim/state_batch: states per batch at most, whole ticks in [1, 1000] (1 = every "
                                  "state on its own); a batch also goes out on every state the policy decides on, a "
                                  "state sent again, and when the physics halts or pauses", range=(1, 1000))
    viewer: bool = option(False, "open MuJoCo's own viewer window (passive, synced to the simulation; needs a "
                                 "display)")

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {self.mode!r}")
        for name in ("rtf", "push_duration", "max_push_force", "resend_timeout", "watchdog_timeout"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be a finite number > 0, got {value}")
        if not (math.isfinite(self.friction) and self.friction >= 0.0):
            raise ValueError(f"friction must be a finite number > 0, or 0 for the model's own, got {self.friction}")
        if not (math.isfinite(self.torso_mass_scale) and self.torso_mass_scale > 0.0):
            raise ValueError(f"torso_mass_scale must be a finite number > 0, got {self.torso_mass_scale}")
        ticks = self.torque_delay / TIMESTEP if math.isfinite(self.torque_delay) else -1.0
        if not (ticks >= 0.0 and abs(ticks - round(ticks)) < 1e-6):
            raise ValueError(f"torque_delay must be a whole number of ms >= 0 s, got {self.torque_delay}")
        for name in ("stop_time", "damping", "markers_rate", "solo_check"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value}")
        if not (math.isfinite(self.clock_rate) and 0.0 < self.clock_rate <= 1000.0):
            raise ValueError(f"clock_rate must be a finite number in (0, 1000] Hz, got {self.clock_rate}")
        if isinstance(self.batch_ticks, bool) or not isinstance(self.batch_ticks, int) \
                or not 1 <= self.batch_ticks <= 1000:
            raise ValueError(f"batch_ticks must be a whole number of ticks in [1, 1000], got {self.batch_ticks!r}")
        if not 0.0 < self.max_late_fraction <= 1.0:
            raise ValueError(f"max_late_fraction must be in (0, 1], got {self.max_late_fraction}")
        if self.stats_file and not Path(self.stats_file).resolve().parent.is_dir():
            raise ValueError(f"stats_file {self.stats_file}: its directory does not exist")
        if self.pairing_key != NO_KEY:
            PairingKey.parse(self.pairing_key)
        try:
            pushes = parse_pushes(self.push_schedule)
        except ValueError as exc:
            raise ValueError(f"push_schedule: {exc}") from None
        if any(abs(p.force_x) > self.max_push_force for p in pushes):
            raise ValueError(f"push_schedule: forces must be within +-{self.max_push_force} N")

    @property
    def model_options(self) -> ModelOptions:
        """The model to simulate: the variant with the foot friction and torso mass."""
        return ModelOptions(self.model, self.friction or None, self.torso_mass_scale)

    @property
    def clock_ticks(self) -> int:
        """Ticks between ``/clock`` messages (``clock_rate`` rounded to whole ticks, >= 1)."""
        return max(1, int(round(1.0 / (self.clock_rate * TIMESTEP))))

    @property
    def delay_ticks(self) -> int:
        """The torque delay in ticks (1 ms each)."""
        return int(round(self.torque_delay / TIMESTEP))

    @property
    def pushes(self) -> tuple[Push, ...]:
        """``push_schedule`` parsed, by time."""
        return parse_pushes(self.push_schedule)

    def describe(self) -> str:
        """One line for the start-up log: the model, its errors, the mode."""
        return (f"{self.model} model"
                + (f", foot friction {self.friction:g}" if self.friction else "")
                + (f", torso mass x{self.torso_mass_scale:g}" if self.torso_mass_scale != 1.0 else "")
                + (f", torque delay {self.torque_delay * 1000:g} ms" if self.torque_delay else "")
                + f", {self.mode} mode" + (f", rtf {self.rtf:g}" if self.mode == "paced" else ""))


SECRET_PARAMS = ("pairing_key",)
"""Parameters read once at start and then removed (``ros2 param get`` must not show them)."""
RUN_TIME_PARAMS = ("push_duration",)
"""Parameters that may change while the node runs (``ros2 param set``); the rest are fixed."""
