"""ROS-free parts of the stack: the speed window, speed clamping, schedule parsing, the
controller's stance inference, gait queuing and alpha bounds."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rabbit_msgs_py.decision_ticks import PER_STEP

from rabbit_hzd_controller.controller import HZDController, Leg, infer_stance
from rabbit_hzd_controller.gait_state import state_on_gait
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.policies import LibraryPolicy, PolicyUnavailable
from rabbit_policy.spec.make import make_policy
from rabbit_policy.runtime.speed_command import clamp_speed
from rabbit_policy.runtime.speed_window import SpeedWindow
from rabbit_policy.experiment.scenario import Push, Scenario, parse_pushes, parse_schedule
from rabbit_policy.bringup.config import StackConfig, ros_arguments

pytestmark = pytest.mark.unit


MS = 1_000_000


def test_speed_window_averages_up_to_a_stamp():
    window = SpeedWindow(size=3)
    for i, v in enumerate([1.0, 2.0, 3.0, 4.0, 5.0]):
        window.add(i * MS, v, desired_speed=3.0)
    obs = window.observation(3.0)
    assert (obs.mean_speed, obs.mean_error) == (4.0, -1.0)  # last three: 3, 4, 5
    obs = window.observation(3.0, stamp_ns=2 * MS)  # samples 1, 2, 3 (stamps 0..2)
    assert (obs.mean_speed, obs.mean_error) == (2.0, 1.0)
    assert window.observation(1.0, stamp_ns=-1).as_tuple() == (1.0, 1.0, 0.0)
    window.add(0, 9.0, 3.0)  # time went back: a reset starts afresh
    assert len(window) == 1 and window.observation(3.0).mean_speed == 9.0
    with pytest.raises(ValueError):
        window.add(MS, math.nan, 1.0)


def test_speed_window_keeps_the_newest_two_windows_and_its_means_are_correctly_rounded():
    """The window finds its samples by bisection and sums them with fsum: the mean is the
    exact sum rounded once, over n (so it does not depend on the order or on what came before),
    over at most ``size`` samples among the newest ``2 * size``, however many were added."""
    from fractions import Fraction

    rng = np.random.default_rng(5)
    window = SpeedWindow(size=50)
    speeds = rng.uniform(0.0, 2.0, 1000) * 10.0 ** rng.integers(-8, 2, 1000)  # badly scaled: order matters
    for i, v in enumerate(speeds):
        window.add(i * MS, float(v), desired_speed=1.0)
        assert len(window) == min(i + 1, 100)
    for stamp, since in [(None, None), (999 * MS, 975 * MS), (960 * MS, None), (930 * MS, 920 * MS)]:
        end = 1000 if stamp is None else stamp // MS + 1
        start = max(end - 50, 900, (since // MS + 1) if since is not None else 0)
        exact = sum(Fraction(float(v)) for v in speeds[start:end])
        assert window.observation(1.0, stamp, since).mean_speed == float(exact) / (end - start)
    assert window.observation(1.0, 880 * MS).as_tuple() == (1.0, 1.0, 0.0)  # older than the newest 100: dropped


def test_exact_sum_is_math_fsum_bit_for_bit():
    """The compiled correctly rounded sum equals math.fsum (one correctly rounded value, whatever
    the algorithm) on badly scaled, cancelling and tie-making data; non-finite input falls back
    to fsum's own rules."""
    from rabbit_policy.runtime.exact_sum import exact_sum

    rng = np.random.default_rng(11)
    cases = [np.zeros(0), np.array([1.0]), np.array([1e100, 1.0, -1e100]), np.array([1.0, 1e-16, 1e-16]),
             np.array([2.0 ** 53, 1.0, 2.0 ** -60]), np.array([2.0 ** 53, 1.0, -(2.0 ** -60)]),  # ties and near-ties
             np.array([0.1] * 10)]
    for _ in range(300):
        n = int(rng.integers(1, 800))
        values = rng.uniform(-1.0, 1.0, n) * 10.0 ** rng.integers(-20, 20, n)
        values = np.concatenate([values, -values[: n // 2] * (1 + 1e-15)])  # heavy cancellation
        cases.append(rng.permutation(values))
    for values in cases:
        got, want = exact_sum(values), math.fsum(values.tolist())
        assert got == want or (math.isnan(got) and math.isnan(want)), values
    assert exact_sum(np.array([math.inf, 1.0])) == math.inf
    with pytest.raises(OverflowError):  # as fsum: an intermediate overflow
        exact_sum(np.array([1e308, 1e308, -1e308]))


def test_clamp_speed():
    assert clamp_speed(1.2, 0.7, 1.5) == 1.2
    assert clamp_speed(9.0, 0.7, 1.5) == 1.5 and clamp_speed(-1.0, 0.7, 1.5) == 0.7
    for bad in (math.nan, math.inf):
        with pytest.raises(ValueError):
            clamp_speed(bad, 0.7, 1.5)


def test_schedule_and_push_parsing():
    assert parse_schedule("0:0.8,10:1.2,20:1.0") == ((0.0, 0.8), (10.0, 1.2), (20.0, 1.0))
    assert parse_pushes("4:-80:0.2,2:60:0.1") == (Push(2.0, 60.0, 0.1), Push(4.0, -80.0, 0.2))
    for bad in ("0:0.8,x", "0:nan", "-1:1.0"):
        with pytest.raises(ValueError):
            parse_schedule(bad)
    with pytest.raises(ValueError):
        parse_pushes("1:50:0")
    with pytest.raises(ValueError):
        StackConfig(duration=5.0, schedule=((1.0, 0.8),))
    with pytest.raises(ValueError):
        StackConfig(duration=5.0, schedule=((0.0, 0.8), (0.0, 1.0)))
    # one spacing rule on every path (walk.py's Scenario, run_stack's StackConfig): 0.1 s
    crowded = tuple((round(k * 0.0002, 4), 0.8 + 0.1 * (k % 2)) for k in range(8000))
    for build in (lambda s: Scenario(schedule=s), lambda s: StackConfig(duration=5.0, schedule=s)):
        with pytest.raises(ValueError, match="at least 0.1 s apart"):
            build(crowded)
        build(((0.0, 0.8), (0.1, 1.0)))  # exactly the spacing is fine


def test_a_layout_is_one_of_three_and_a_cpu_meter_counts_per_tick():
    import os

    from rabbit_policy.bringup.config import LAYOUTS
    from rabbit_policy.bringup.cpu import CpuMeter, process_cpu_seconds

    assert StackConfig(duration=1.0, schedule=((0.0, 1.0),)).layout == "composed" == LAYOUTS[0]
    with pytest.raises(ValueError, match="layout must be one of composed, separate, in-process"):
        StackConfig(duration=1.0, schedule=((0.0, 1.0),), layout="components")
    meter = CpuMeter({"me": os.getpid()})
    assert meter.per_tick_us(5_000_000) is None and not meter.started  # not started: nothing measured
    meter.start(1_000_000)
    spent = process_cpu_seconds(os.getpid())
    while process_cpu_seconds(os.getpid()) < spent + 0.05:  # burn at least 50 ms of CPU
        pass
    per_tick = meter.per_tick_us(1_000_000 + 100 * 1_000_000)  # over 100 ticks
    assert per_tick["me"] >= 0.05 / 100 * 1e6 and per_tick["total"] == per_tick["me"]
    assert meter.per_tick_us(1_000_000) is None  # no ticks
    assert process_cpu_seconds(2 ** 30) is None  # no such process


def test_ros_arguments():
    assert ros_arguments({"mode": "lockstep", "stop_time": 5.0, "start_paused": True, "gait_dir": ""}) == [
        "--ros-args", "-p", "mode:=lockstep", "-p", "stop_time:=5.0", "-p", "start_paused:=true",
    ]


@pytest.mark.parametrize("stance", [Leg.LEFT, Leg.RIGHT])
@pytest.mark.parametrize("tau", [0.0, 0.3, 0.7])
def test_infer_stance_on_the_gait(stance, tau):
    gait = GaitLibrary.load().nearest(1.0)
    q, _ = state_on_gait(gait.alpha, gait.speed, tau=tau, stance=stance)
    assert infer_stance(q) is stance


def test_alpha_outside_joint_waypoint_bounds_is_rejected():
    gait = GaitLibrary.load().nearest(1.0)
    controller = HZDController(gait.alpha, gait.kd)
    with pytest.raises(ValueError, match="outside the bounds"):
        controller.set_alpha([a + 2.0 for a in gait.alpha])
    with pytest.raises(ValueError):
        controller.queue_kd(1e6)
    assert controller.pending_alpha is None and controller.pending_kd is None


def test_policies():
    library = GaitLibrary.load()
    from rabbit_policy.runtime.policies import CLASSIC_DECISION_PERIOD, PeriodicPolicy, decision_period
    from rabbit_policy.runtime.speed_window import Observation

    policy = make_policy("classic", mode="interpolate", decision=PER_STEP)
    assert isinstance(policy, LibraryPolicy) and decision_period(policy) == 0
    periodic = make_policy("classic")  # the default: calibrated interpolation, every 20 ticks
    assert isinstance(periodic, PeriodicPolicy) and decision_period(periodic) == CLASSIC_DECISION_PERIOD
    assert periodic.policy.mode == "interpolate"
    for bad in (-1, 2.5, True, None):
        with pytest.raises(ValueError, match="DecisionTiming"):
            make_policy("classic", decision=bad)


    command = policy.act(Observation(1.05, 0.9, 0.15))
    expected = library.interpolate(1.05)
    assert command.alpha == expected.alpha and command.kd == expected.kd
    with pytest.raises(PolicyUnavailable, match="does not exist"):
        make_policy("learned", policy_file="/nonexistent/policy.pt")
    with pytest.raises(ValueError):
        make_policy("classic", mode="best")


def test_a_decision_timing_is_parsed_formatted_and_checked_in_one_place():
    from rabbit_msgs_py.decision_ticks import OWN, DecisionTiming

    assert [DecisionTiming.parse(t) for t in ("own", "-1", "step", "0", "20", " 20 ")] == \
        [OWN, OWN, PER_STEP, PER_STEP, DecisionTiming(20), DecisionTiming(20)]
    assert [str(t) for t in (OWN, PER_STEP, DecisionTiming(20))] == ["own", "step", "20"]
    assert [t.param for t in (OWN, PER_STEP, DecisionTiming(20))] == [-1, 0, 20]  # the node parameter
    assert DecisionTiming.parse(-1) == OWN and DecisionTiming.parse(DecisionTiming(7).param) == DecisionTiming(7)
    assert OWN.resolve(20) == 20 and PER_STEP.resolve(20) == 0
    for bad in ("-2", "2.5", "sometimes", ""):
        with pytest.raises(ValueError, match="own, step or a whole number of ticks"):
            DecisionTiming.parse(bad)
    for bad in (-1, 2.5, True):
        with pytest.raises(ValueError):
            DecisionTiming(bad)


def test_learned_policy_checkpoint_round_trip(tmp_path):
    import torch

    from rabbit_hzd_controller.controller import ControllerConfig, validate_alpha
    from rabbit_policy.learning.env import RabbitHZDEnv
    from rabbit_policy.runtime.network import HZDPolicyNet, PolicyCheckpoint, parameter_count
    from rabbit_policy.runtime.speed_window import Observation

    bounds = RabbitHZDEnv().bounds
    torch.manual_seed(0)
    net = HZDPolicyNet(bounds.low, bounds.high)
    assert parameter_count(net) == 633  # 620 in the paper's count + Kd as the 21st output
    path = tmp_path / "policy.pt"
    PolicyCheckpoint(net.state_dict(), bounds.low, bounds.high, {"algo": "untrained"}).save(path)
    policy = make_policy("learned", policy_file=path)
    command = policy.act(Observation(1.2, 1.1, 0.1))
    validate_alpha(command.alpha, ControllerConfig())  # a gait the controller accepts
    assert bounds.low[-1] <= command.kd <= bounds.high[-1]
    (tmp_path / "broken.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(PolicyUnavailable, match="cannot load"):
        make_policy("learned", policy_file=tmp_path / "broken.pt")
    with pytest.raises(PolicyUnavailable, match="does not exist"):
        make_policy("learned", policy_file=tmp_path / "missing.pt")


def test_rate_limited_policy_moves_the_command_by_at_most_its_step():
    from rabbit_policy.runtime.policies import RateLimitedPolicy
    from rabbit_policy.runtime.speed_window import Observation

    seen = []

    class Recorder:
        name = "recorder"

        def act(self, observation):
            seen.append(observation)
            return None

    limited = RateLimitedPolicy(Recorder(), 0.1)
    limited.act(Observation(1.5, 1.5, 0.0))  # starts at the requested command
    limited.act(Observation(1.0, 1.5, -0.4))
    limited.act(Observation(1.0, 1.45, -0.45))
    assert [round(o.desired_speed, 9) for o in seen] == [1.5, 1.4, 1.3]
    # the error input is consistent with the limited command: mean(v_d - v) + (limited - requested)
    assert seen[1].mean_error == pytest.approx(-0.4 + 0.4) and seen[2].mean_error == pytest.approx(-0.45 + 0.3)
    assert limited.name == "recorder+limit0.1"
    with pytest.raises(ValueError):
        RateLimitedPolicy(Recorder(), 0.0)
    assert make_policy("classic", "", "nearest", max_command_step=0.2, decision=PER_STEP).name == \
        "classic/nearest+limit0.2"


def test_a_huge_command_logs_a_short_line():
    from rabbit_policy.runtime.speed_command import clamp_message

    line = clamp_message(1e308, 0.7, 1.5, 1.5, "/cmd_speed")
    assert "1e+308" in line and len(line) < 100


def test_a_schedule_outside_the_command_range_is_clamped_and_said_once_per_entry():
    from rabbit_policy.runtime.speed_command import clamp_schedule

    schedule, lines = clamp_schedule(((0.0, 0.3), (5.0, 1.0), (9.0, 2.0)))
    assert schedule == ((0.0, 0.7), (5.0, 1.0), (9.0, 1.5))
    assert lines == ["the command at t = 0 s, 0.3 m/s is outside [0.7, 1.5]; clamped to 0.70 m/s",
                     "the command at t = 9 s, 2 m/s is outside [0.7, 1.5]; clamped to 1.50 m/s"]
    with pytest.raises(ValueError, match="finite"):
        clamp_schedule(((0.0, float("nan")),))


def test_calibrated_interpolation_picks_the_blend_measured_to_walk_at_the_command():
    from rabbit_policy.runtime.gait_library import Calibration

    library = GaitLibrary.load()
    assert library.calibration is not None  # shipped: interpolation.json beside the gaits
    bare = GaitLibrary(library.gaits)
    # a made-up calibration for three gaits: the first pair's middle blends fail, the
    # second pair walks faster than its design speeds in the middle
    three = GaitLibrary(library.gaits[:3])
    lo, mid, hi = three.speeds
    calibration = Calibration((((0.0, lo), (0.5, None), (1.0, mid)),
                               ((0.0, mid), (0.5, hi + 0.2), (1.0, hi))))
    calibrated = GaitLibrary(three.gaits, calibration)
    # between the first two gaits only the failed middle would bracket: the nearest gait instead
    between = 0.5 * (lo + mid)
    assert calibrated.interpolate(between).alpha == three.nearest(between).alpha
    # a speed the second pair's blends walk at: the blend by measured speed, not by design speed
    target = hi + 0.1
    chosen = calibrated.interpolate(min(target, hi))  # hi itself: its own gait (clamped)
    assert chosen.alpha == three.gaits[-1].alpha
    w = calibration.weight_for(1, mid + 0.5 * (hi - mid))
    assert w is not None and 0.0 < w < 0.5 + 1e-9
    assert bare.interpolate(1.05).info["weight"] == pytest.approx((1.05 - 1.0) / 0.1)
    with pytest.raises(ValueError, match="covers"):
        GaitLibrary(library.gaits[:2], calibration)


@pytest.mark.parametrize("content", ["{}", "[1, 2]", "not json", '{"speed": "fast"}'])
def test_a_gait_directory_holding_no_gait_is_one_line_and_exit_2(tmp_path, content):
    """``--gait-dir`` with a file that is not a gait: one line naming it, exit status 2
    (bad input), never a traceback or 1 (1 means fell or stalled)."""
    import subprocess
    import sys
    from pathlib import Path

    (tmp_path / "gait_1.00.json").write_text(content)
    script = Path(__file__).resolve().parents[2] / "scripts" / "walk.py"
    out = subprocess.run([sys.executable, str(script), "--gait-dir", str(tmp_path), "--duration", "0.1"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, out.stderr
    lines = [line for line in out.stderr.splitlines() if line.strip()]
    assert "Traceback" not in out.stderr and "gait_1.00.json" in lines[-1] and "not a gait file" in lines[-1]


def test_a_file_for_the_other_controller_is_refused_not_ignored():
    """--policy-file with classic, or a gait directory with learned, would be silently
    unused: each is a one-line error instead (every entry point builds policies here)."""
    with pytest.raises(ValueError, match="for the learned controller"):
        make_policy("classic", policy_file="runs/es0/best.pt")
    with pytest.raises(ValueError, match="the learned one takes a policy file"):
        make_policy("learned", gait_dir="my_gaits")


def test_decision_clock_once_per_step_and_every_n_ticks():
    """The rule policy_node and ClosedLoop share (stamps: sim time in ticks here)."""
    from rabbit_policy.runtime.decision_clock import DecisionClock

    clock = DecisionClock(0, window=1000)
    assert clock.sample(0, 5.0, 1.0) == []  # the placed state is no sample
    for stamp in range(1, 11):
        assert clock.sample(stamp, 1.0 if stamp <= 5 else 2.0, 1.5) == []
        assert clock.sample(stamp, 9.0, 1.5) == []  # a state sent again (lockstep re-send) is one sample
    assert clock.switch(4, 1.5)[0].mean_speed == pytest.approx(1.0)  # samples 1..5: the state after the switch
    assert clock.switch(12, 1.5) == []  # its next sample (13) is not in yet
    (due,) = clock.sample(13, 2.0, 1.5)
    assert due.mean_speed == 2.0 and due.mean_error == pytest.approx(-0.5)  # samples 6..13
    periodic = DecisionClock(5, window=1000)
    decided = [stamp for stamp in range(1, 31) for _ in periodic.sample(stamp, 1.0, 1.0)]
    assert decided == [5, 10, 15, 20, 25, 30]  # multiples of the period since the placement
    periodic.switch(30, 1.0)
    periodic.switch(40, 1.0)
    for stamp in range(31, 45):
        due = periodic.sample(stamp, float(stamp), 1.0)
    assert due == [] and periodic.sample(45, 45.0, 1.0)[0].mean_speed == pytest.approx(sum(range(36, 46)) / 10)
    assert periodic.sample(3, 1.0, 1.0) == [] and periodic.window.newest_stamp == 3  # a reset: afresh


def test_a_speed_schedule_applies_each_change_at_the_first_state_at_or_after_its_time():
    """One rule for ClosedLoop and policy_node (stamps in ns, 1 ns of slack for decimal
    seconds; several changes due at once: the last), started over after a reset."""
    from rabbit_policy.runtime.speed_schedule import SpeedSchedule

    schedule = SpeedSchedule(((1.0, 1.2), (6.132268422788288, 1.416), (6.2, 0.8)))
    assert schedule.due(999_000_000) is None
    assert schedule.due(999_999_999) == 1.2  # 1 ns short of 1 s: the float sum of 1000 ms steps
    assert schedule.due(1_000_000_000) is None  # applied once
    assert schedule.next_stamp == 6_132_268_423
    assert schedule.due(6_132_000_000) is None and schedule.due(6_133_000_000) == 1.416  # the first state after
    assert schedule.due(7_000_000_000) == 0.8 and schedule.next_stamp is None
    schedule.restart()
    assert schedule.due(10_000_000_000) == 0.8  # all at once: the last


def test_policy_node_takes_a_speed_schedule_checked_as_walk_pys():
    from rabbit_policy.policy_driver import speed_schedule

    assert speed_schedule("", 1.0) is None
    assert speed_schedule("2:1.2,4.5:0.9", 1.0).changes == ((2_000_000_000, 1.2), (4_500_000_000, 0.9))
    for text, message in (("0:1.2", "times must increase"), ("2:1.2,2.05:1.0", "at least 0.1 s apart"),
                          ("2-1.2", "time:speed")):
        with pytest.raises(ValueError, match=message):
            speed_schedule(text, 1.0)


@pytest.mark.parametrize("output, inputs", [("sigmoid", 3), ("clip", 25), ("tanh", 30)])
def test_the_numpy_forward_pass_is_torchs_within_float32_rounding(output, inputs):
    """Issue 38 item 2: the network decides without torch; every output within 1e-6 of its
    range of torch's, on random weights (large enough to reach the clip and saturations)."""
    import torch

    from rabbit_policy.runtime.network import HZDPolicyNet, NetworkForward

    rng = np.random.default_rng(inputs)
    low = rng.uniform(-1.5, 0.0, 21)
    high = low + rng.uniform(0.1, 150.0, 21)
    torch.manual_seed(inputs)
    net = HZDPolicyNet(low, high, output=output, inputs=inputs)
    with torch.no_grad():
        for p in net.parameters():
            p.mul_(3.0)
    forward = NetworkForward.of(net)
    x = (rng.normal(size=(500, inputs)) * net.scale.numpy() * 2 + net.offset.numpy()).astype(np.float32)
    with torch.no_grad():
        expected = net(torch.as_tensor(x)).numpy().astype(float)
    got = np.array([forward(row) for row in x])
    assert np.max(np.abs(got - expected) / (high - low)) < 1e-6
    with torch.no_grad():
        for p in net.parameters():
            p.zero_()
    assert np.array_equal(forward(x[0]), got[0])  # a snapshot: the network's later weights do not reach it


def test_quiet_samples_added_at_once_are_the_samples_added_one_by_one():
    """DecisionClock.add_quiet (the compiled loop's samples between two decisions) against
    sample() on each: the same observations after, and a run that would hold a decision is
    refused."""
    from rabbit_policy.runtime.decision_clock import DecisionClock

    rng = np.random.default_rng(3)
    speeds = (1.0 + 0.1 * rng.standard_normal(300)).tolist()
    for period in (0, 20):
        one, many = DecisionClock(period, 100), DecisionClock(period, 100)
        decided = []
        for i, v in enumerate(speeds[:45], start=1):
            decided += one.sample(i, v, 1.1)
        many.add_quiet(range(1, 20), speeds[:19], 1.1)
        decided_many = many.sample(20, speeds[19], 1.1)
        many.add_quiet(range(21, 40), speeds[20:39], 1.1)
        decided_many += many.sample(40, speeds[39], 1.1)
        many.add_quiet(range(41, 46), speeds[40:45], 1.1)
        assert decided == decided_many
        assert one.observe(1.1) == many.observe(1.1)
        if period:
            with pytest.raises(ValueError, match="not quiet"):
                many.add_quiet(range(46, 70), speeds[45:69], 1.1)  # 60 is due


def test_a_policy_copy_shares_what_no_decision_changes_and_copies_its_memory():
    """``copy_policy`` (the return map's and the ceiling's copies, a few per map evaluation)
    shares the network, its forward pass and the gait libraries, and copies the memory: the
    copy decides as the original would, and its decisions leave the original's memory as
    it was."""
    from rabbit_policy.runtime.policies import copy_policy
    from rabbit_policy.runtime.speed_window import Observation

    policy = make_policy("learned")
    copied = copy_policy(policy)
    assert copied.net is policy.net and copied.forward is policy.forward
    assert copied.residual.library is policy.residual.library
    assert copied.memory is not policy.memory
    body = (0.0, 0.0, 0.3, 2.0, 0.9)  # the shipped policy's recovery rule reads the body state
    observation = Observation(1.0, 0.9, 0.1, body)
    assert copied.act(observation) == policy.act(observation)  # the same decision from the same memory
    before = copy_policy(policy)
    copied.act(Observation(1.0, 0.5, 0.5, body))
    assert before.act(observation) == policy.act(observation)  # the copy's decisions left the original alone
    recovery = make_policy("recovery")
    assert copy_policy(recovery).classic.library is recovery.classic.library

