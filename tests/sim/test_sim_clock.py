"""Sim time counted in ticks (issue 76): MuJoCo's ``data.time`` is a float sum of 1 ms steps that
leaves the ns grid from tick 180,963 on (180963000001 ns); the simulator's stamps, and every
rule that tests a stamp exactly (/clock every 10 ms, the batch grid, the state before a
decision), come from the tick count instead. Provoked directly: a simulator placed at that
tick with MuJoCo's drifted time beside it, no three-minute walk."""

from __future__ import annotations

import pytest

from rabbit_hzd_controller.gait_state import state_on_gait
from rabbit_msgs_py.decision_ticks import PeriodicDecisions, precedes_decision
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_sim.physics.model import load_model
from rabbit_sim.stepping.settings import SimSettings
from rabbit_sim.physics.simulation import Simulator, timestep_ns
from rabbit_sim.stepping import SimDriver, State
from rabbit_sim.stepping.batch import StateBatcher

from fake_clock import FakeClock

pytestmark = pytest.mark.unit

MS = 1_000_000  # ns
DRIFT_TICK = 180_963  # the first tick whose float sum of 1 ms steps rounds off the ns grid


def float_sum_time(ticks: int, timestep: float = 0.001) -> float:
    """MuJoCo's clock after ``ticks`` steps: ``data.time += timestep`` each step."""
    t = 0.0
    for _ in range(ticks):
        t += timestep
    return t


def test_mujoco_float_time_leaves_the_ns_grid_where_the_issue_found_it():
    assert round(float_sum_time(DRIFT_TICK - 1) * 1e9) % MS == 0
    assert round(float_sum_time(DRIFT_TICK) * 1e9) == DRIFT_TICK * MS + 1  # the premise of the tests below


def test_the_timestep_must_be_whole_ns():
    assert timestep_ns(0.001) == MS and timestep_ns(0.0005) == 500_000
    with pytest.raises(ValueError, match="whole number of ns"):
        timestep_ns(1.5e-10)


@pytest.fixture(scope="module")
def initial_state() -> tuple[list[float], list[float]]:
    qpos, qvel = state_on_gait(GaitLibrary.load().nearest(1.0).alpha, 1.0)
    return list(qpos), list(qvel)


def _at_drift_tick(sim: Simulator) -> None:
    """Put the simulator's clock at :data:`DRIFT_TICK`, with MuJoCo's drifted float time beside it."""
    sim.tick = DRIFT_TICK
    sim.data.time = float_sum_time(DRIFT_TICK)


def test_the_simulators_time_counts_ticks_not_mujocos_float_sum(initial_state):
    sim = Simulator(load_model("paper"))
    sim.reset(*initial_state)
    assert (sim.tick, sim.stamp, sim.time) == (0, 0, 0.0)
    _at_drift_tick(sim)
    for k in range(1, 2001):
        sim.step([0.0] * 4)
        assert sim.stamp == (DRIFT_TICK + k) * MS and sim.time == sim.stamp / 1e9
    assert round(sim.data.time * 1e9) != sim.stamp  # MuJoCo's own clock went its way; nothing reads it
    sim.reset(*initial_state)
    assert sim.tick == 0 and sim.stamp == 0


def test_a_push_past_the_drift_tick_starts_on_its_tick(initial_state):
    sim = Simulator(load_model("paper"))
    sim.reset(*initial_state)
    _at_drift_tick(sim)
    from rabbit_msgs_py.pushes import Push

    sim.schedule_pushes([Push((DRIFT_TICK + 5) / 1000, -60.0, 0.01)])
    started = []
    for _ in range(30):
        sim.step([0.0] * 4)
        if sim.push_changed:
            started.append((sim.tick, sim.push_wrench[0]))
    assert started == [(DRIFT_TICK + 5, -60.0), (DRIFT_TICK + 15, 0.0)]  # on its tick, for 10 ticks


def test_the_drivers_stamps_stay_on_the_ms_grid_past_the_drift_tick(initial_state):
    """sim_node's states: every stamp a whole ms, so /clock's, the batch grid's and the policy's
    exact tests on stamps hold however long the walk has run."""
    driver = SimDriver(SimSettings(), Simulator(load_model("paper")), FakeClock(), shapes=False)
    driver.on_initial_state(*initial_state)
    _at_drift_tick(driver.sim)
    stamp, stamps = 0, []
    for _ in range(200):
        states = [a for a in driver.on_torques(stamp, "hzd_controller_node/c", [0.0] * 4, 100.0)
                  if isinstance(a, State)]
        (state,) = states
        stamp = state.stamp
        stamps.append(stamp)
    assert stamps == [(DRIFT_TICK + k) * MS for k in range(1, 201)]
    clock_every = 10 * MS  # /clock at 100 Hz: state_topics' rule
    assert sum(s % clock_every == 0 for s in stamps) == 20
    assert sum(precedes_decision(s, 20) for s in stamps) == 10  # /hzd/phase before each decision
    batcher = StateBatcher(20)
    assert sum(batcher.add(s, [0.0] * 7, [0.0] * 7, [0.0] * 7) for s in stamps) >= 10
    due = PeriodicDecisions(20, MS)
    due.join(stamps[0])
    assert sum(due.due(s) for s in stamps[1:]) == 10
