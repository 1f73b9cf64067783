"""The learning issue's ablation rows c (the body state inside the step) and d (the action
as a bounded residual on the calibrated library): what each means, in the environment, in
the closed loop, through train.py and in the node."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rabbit_msgs_py.node_runner import NodeStartError
from rabbit_policy.experiment.loop import ClosedLoop
from rabbit_policy.experiment.scenario import Push, Scenario
from rabbit_policy.learning.env import EpisodeConfig, RabbitHZDEnv
from rabbit_policy.learning.warm_start import zero_residual_network
from rabbit_policy.runtime.actions import ActionBounds, ResidualAction, policy_bounds
from rabbit_policy.runtime.body import BodyStateBuffer
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.memory import INPUTS, MemoryConfig, SpeedMemory
from rabbit_policy.runtime.policies import NetworkPolicy, RateLimitedPolicy
from rabbit_policy.spec.make import make_policy


ROOT = Path(__file__).resolve().parents[2]
LIBRARY = GaitLibrary.load()


def zero_residual_policy(features: str = "body", integral_gain: float = 0.0) -> NetworkPolicy:
    bounds = policy_bounds("residual", LIBRARY)
    net = zero_residual_network(bounds.low, bounds.high, INPUTS[features], seed=3)
    memory = MemoryConfig.for_features(features, 20, integral_gain, LIBRARY.speed_range)
    return NetworkPolicy(net, decision_period=20, memory=None if memory is None else SpeedMemory(memory),
                         residual=ResidualAction(LIBRARY, ActionBounds.from_library(LIBRARY),
                                                 integral_gain=integral_gain))


def _state(pitch: float, pitch_rate: float, hip_velocity: float) -> tuple[list[float], list[float]]:
    return [0.1, 0.8, pitch, 0.0, 0.0, 0.0, 0.0], [hip_velocity, 0.0, pitch_rate, 0.0, 0.0, 0.0, 0.0]


@pytest.mark.unit
def test_the_body_state_buffer_waits_for_the_state_and_the_phase_before_it_in_any_order():
    """policy_node's rule, as the loops': the state decided on, the phase computed on the
    state before it; the parts may come in any order, a skipped phase is read at the newest
    state before, a decision whose parts never come expires, a placement starts afresh."""
    buffer = BodyStateBuffer(tick=10, horizon=5)
    assert buffer.body_at(30) is None
    buffer.add_phase(20, 0.25, 2.0)
    buffer.add_phase(30, 0.27, 2.1)  # the phase on the state decided on is not the one used
    assert buffer.body_at(30) is None  # the state is not in yet
    buffer.add_state(30, *_state(0.05, -0.3, 1.1))
    assert buffer.body_at(30) == (0.05, -0.3, 0.25, 2.0, 1.1)
    buffer.add_state(40, *_state(0.06, -0.2, 1.2))
    assert buffer.body_at(40) == (0.06, -0.2, 0.27, 2.1, 1.2)
    buffer.add_state(60, *_state(0.07, -0.1, 1.3))  # the controller has not answered 50 yet: wait
    assert buffer.body_at(60) is None and not buffer.expired(60)
    buffer.add_phase(60, 0.31, 2.2)  # it skipped 50 (free-running) and answered 60: read at 40
    assert buffer.body_at(60) == (0.07, -0.1, 0.27, 2.1, 1.3)
    for stamp in range(70, 130, 10):  # the controller stops answering after 60
        buffer.add_state(stamp, *_state(0.0, 0.0, 1.0))
    assert buffer.body_at(80) is None and not buffer.expired(80)  # 4 ticks on
    buffer.add_state(130, *_state(0.0, 0.0, 1.0))
    assert buffer.expired(80) and not buffer.expired(90)  # 5 ticks on: given up
    buffer.add_state(10, *_state(0.0, 0.0, 1.0))  # placed again
    assert buffer.body_at(30) is None and buffer.body_at(10) is None
    buffer.add_phase(0, 0.0, 0.0)
    assert buffer.body_at(10) == (0.0, 0.0, 0.0, 0.0, 1.0)
    with pytest.raises(ValueError, match="whole numbers"):
        BodyStateBuffer(tick=0)


@pytest.mark.sim
def test_the_body_state_needs_a_decision_period_and_unknown_choices_are_refused():
    with pytest.raises(ValueError, match="needs a decision period"):
        MemoryConfig.for_features("body", 0)
    with pytest.raises(ValueError, match="needs a decision period"):
        EpisodeConfig(features="body", decision_period=0)
    with pytest.raises(ValueError, match="action must be one of"):
        EpisodeConfig(action="delta")
    with pytest.raises(ValueError, match="symmetric"):
        zero_residual_network(np.zeros(21), np.ones(21), 3, seed=0)
    with pytest.raises(ValueError, match="needs the body state"):
        SpeedMemory(MemoryConfig.for_features("body", 20)).inputs(np.array([1.0, 1.0, 0.0]))
    with pytest.raises(ValueError, match="needs action residual"):
        EpisodeConfig(features="memory", integral_gain=0.3)
    with pytest.raises(ValueError, match="needs features memory or body"):
        EpisodeConfig(action="residual", integral_gain=0.3)
    with pytest.raises(ValueError, match="integral_gain must be"):
        RabbitHZDEnv(action="residual", features="memory", decision_period=20, integral_gain=-1.0)


@pytest.mark.slow
@pytest.mark.sim
def test_a_zero_residual_is_the_classic_controller_bit_for_bit_through_a_speed_change_and_a_push():
    """Row d starts exactly from classic HZD: the zero residual walks the same trajectory,
    also when the rate-limit wrapper carries the body state through."""
    scenario = Scenario(schedule=((0.0, 0.8), (1.5, 1.3)), pushes=(Push(2.5, -80.0, 0.1),))
    final = []
    for policy in (zero_residual_policy(), RateLimitedPolicy(zero_residual_policy(), 10.0),
                   make_policy("classic")):
        loop = ClosedLoop(scenario, policy)
        loop.run(4.0)
        assert not loop.failed
        final.append(loop.data.qpos.copy())
    assert np.array_equal(final[0], final[2]) and np.array_equal(final[1], final[2])


@pytest.mark.sim
def test_a_zero_residual_on_the_speed_integral_is_classic_with_that_integral_bit_for_bit():
    """With an integral gain the residual's base gait is offset by the memory's integral, the
    same arithmetic as the classic controller's speed integral: the zero residual walks the
    very same trajectory as classic + integral (a model that walks too slow, so the integral
    works), not classic's."""
    from rabbit_sim.physics.model import ModelOptions

    for speed in (1.0, 1.45):  # at 1.45 m/s the integral is held where the gait reaches the library's 1.5
        scenario = Scenario(schedule=((0.0, speed),), model=ModelOptions("drives"))
        residual, integral = zero_residual_policy("memory", 0.3), make_policy("classic", speed_integral=0.3)
        final = []
        for policy in (residual, integral, make_policy("classic")):
            loop = ClosedLoop(scenario, policy)
            loop.run(3.0)
            assert not loop.failed
            final.append(loop.data.qpos.copy())
        assert np.array_equal(final[0], final[1]) and not np.array_equal(final[1], final[2])
        assert residual.memory.integral == integral.policy.integral.value
    assert integral.policy.integral.value == pytest.approx((1.5 - 1.45) / 0.3)  # v_d + 0.3 I = 1.5: held there
    env = RabbitHZDEnv(max_steps=20, decision_period=20, features="memory", action="residual", integral_gain=0.3)
    assert env.memory.config.integral.limit == pytest.approx(0.2 / 0.3)  # the offset's bound: 0.2 m/s
    assert env.observation_space.high[3] == pytest.approx(0.2 / 0.3, rel=1e-6)


@pytest.mark.sim
def test_the_body_observation_is_the_loops_state_and_the_residual_action_zero_is_the_library_gait():
    env = RabbitHZDEnv(max_steps=50, decision_period=20, features="body", action="residual")
    assert env.observation_space.shape == (30,) and env.action_space.shape == (21,)
    obs, _ = env.reset(seed=4, options={"desired_speed": 1.2, "next_speed": 1.2})
    assert env.observation_space.contains(obs)
    for _ in range(5):
        obs, _r, terminated, _t, info = env.step(np.zeros(21, dtype=np.float32))
        assert not terminated and not info["rejected"]
    loop = env.loop
    assert np.allclose(obs[25:], loop.body_state(), atol=1e-6)  # pitch, rate, phase, rate, hip velocity
    assert obs[25] == pytest.approx(loop.data.qpos[2], abs=1e-6) and obs[29] == pytest.approx(loop.data.qvel[0], abs=1e-6)
    assert 0.0 <= obs[27] <= 1.0 and obs[28] > 0.0  # the phase moves forward
    gait = LIBRARY.interpolate(1.2)
    assert np.allclose(loop.controller.alpha, gait.alpha) and loop.controller.kd == pytest.approx(gait.kd)
    assert np.array_equal(obs[4:25], np.zeros(21, dtype=np.float32))  # the last action: the zero residual
    env.step(np.ones(21, dtype=np.float32))  # the residual's upper bound: + 0.1 rad on each, + 20 on Kd
    assert loop.controller.kd == pytest.approx(gait.kd + 20.0)
    with pytest.raises(ValueError, match="needs a decision period"):
        RabbitHZDEnv(decision_period=0, features="body")


@pytest.mark.slow
@pytest.mark.ros
def test_a_body_and_residual_run_ships_a_policy_that_every_loop_runs_policy_node_too(tmp_path):
    """Row d through train.py (its preset, one short generation): the checkpoint says its
    features, action and residual; the learned policy from it is the zero residual's
    classic start moved by the trained residual; policy_node runs it (deciding every 20
    ticks: once per step is refused with one line)."""
    out = tmp_path / "d"
    result = subprocess.run([sys.executable, "scripts/train.py", "--config", "config/train/ablation_d_es_moderate.yaml",
                             "--out", str(out), "--iterations", "1", "--pairs", "1", "--episodes", "1",
                             "--max-steps", "30", "--eval-every", "0", "--no-progress"],
                            capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    policy = make_policy("learned", policy_file=out / "policy.pt")
    info = policy.checkpoint.info
    assert (info["features"], info["action"], info["output"]) == ("body", "residual", "tanh")
    assert policy.needs_body and policy.residual is not None and policy.forward.inputs == 30
    assert policy.decision_period == 20
    loop = ClosedLoop(Scenario.constant(1.0), policy)
    loop.run(2.0)
    assert not loop.failed and len(loop.decisions) >= 90
    from rabbit_policy.policy_node import PolicyNode
    from ros_helpers import ros_context

    with ros_context() as (context, _executor):
        node = PolicyNode(context=context, policy="learned", policy_file=str(out / "policy.pt"))
        assert node.needs_body and node.decision_period == 20  # it builds the body state from the topics
        assert node.count_publishers("/hzd/alpha") == 1
        node.destroy_node()
        with pytest.raises(NodeStartError, match="reads the body state") as error:
            PolicyNode(context=context, policy="learned", policy_file=str(out / "policy.pt"), decision_period=0)
    assert "\n" not in str(error.value)


@pytest.mark.slow
@pytest.mark.sim
def test_the_poincare_analysis_runs_a_body_state_policy_and_a_zero_residual_is_classics_map():
    """Check 6 on rows c/d: the return map gives the policy the body state at its decisions
    (it raised before), and the zero residual's map is classic HZD's."""
    from rabbit_policy.evaluation.stability import analyse_stability

    zero = analyse_stability(zero_residual_policy(), 1.0, True, samples=20).to_dict()
    classic = analyse_stability(make_policy("classic"), 1.0, True, samples=20).to_dict()
    assert zero["magnitudes"] == classic["magnitudes"] and max(zero["magnitudes"]) < 1.0
    from rabbit_policy.evaluation.acceptance import policy_outputs

    assert policy_outputs(zero_residual_policy()) == 21  # check 6's count: it raised for a body policy
