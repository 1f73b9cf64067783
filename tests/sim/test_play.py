"""``scripts/play.py``: a recorded bag replayed on its topics and recorded again gives the
same messages (counts and contents, per topic, in order); topic selection, ``/clock`` from
the log time, and one-line errors."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import pytest

from rabbit_policy.bringup.config import StackConfig

from rabbit_policy.bringup.in_process import run_in_process
from ros_helpers import ros_context

pytestmark = [pytest.mark.ros, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("play") / "original"
    report, _nodes = run_in_process(StackConfig(duration=1.0, schedule=((0.0, 1.0),), record=str(path)))
    assert report.completed
    return path


def _messages(bag: Path) -> dict[str, list[bytes]]:
    from rosbags.rosbag2 import Reader

    out: dict[str, list[bytes]] = defaultdict(list)
    with Reader(bag) as reader:
        for connection, _t, raw in reader.messages():
            out[connection.topic].append(bytes(raw))
    return out


def _same_payload(recorded: bytes, replayed: bytes) -> bool:
    """Equal CDR, up to the zero padding DDS adds to a multiple of 4 bytes on the wire."""
    return replayed[:len(recorded)] == recorded and not any(replayed[len(recorded):])


def _replay_and_record(bag: Path, out: Path, play_args: list[str], record_args: list[str]) -> subprocess.CompletedProcess:
    recorder = subprocess.Popen([sys.executable, "scripts/record.py", str(out), *record_args], cwd=ROOT,
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        for line in recorder.stdout:  # the recorder has created its subscriptions
            if "recording" in line:
                break
        # play waits for the recorder's subscriptions and, at the end, for every reliable
        # message to be acknowledged; the recorder drains its queue before closing: no sleep
        # decides whether a loaded machine loses a message
        played = subprocess.run([sys.executable, "scripts/play.py", str(bag), "--delay", "0",
                                 "--wait-for-subscribers", "60", *play_args],
                                cwd=ROOT, capture_output=True, text=True, timeout=300)
    finally:
        recorder.send_signal(signal.SIGINT)
        recorder.communicate(timeout=60)
    assert recorder.returncode == 0
    return played


def test_replay_recorded_again_is_the_same_bag(bag, tmp_path):
    played = _replay_and_record(bag, tmp_path / "replay", [], [])
    assert played.returncode == 0, played.stderr
    original, replayed = _messages(bag), _messages(tmp_path / "replay")
    assert set(replayed) == set(original)
    for topic, messages in original.items():
        assert len(replayed[topic]) == len(messages), topic
        assert all(_same_payload(a, b) for a, b in zip(messages, replayed[topic])), topic


def test_every_publisher_of_a_replay_keeps_what_a_reliable_reader_has_not_acknowledged(bag):
    """A replay behind its pace publishes in bursts; a publisher keeping fewer samples than a
    burst overwrites ones a loaded reader has not acknowledged yet (the ``/clock`` publisher
    kept 10: a replay under load once recorded 59 of its 64 clocks)."""
    from rabbit_sim.player import MIN_DEPTH, BagPlayer

    with ros_context() as (context, executor):
        player = BagPlayer(bag, ["/joint_states"], 2.0, 100.0, context=context)
        executor.add_node(player)
        assert player._clock_pub is not None
        assert all(pub.qos_profile.depth >= MIN_DEPTH for pub in player._played_publishers())


def test_replay_of_chosen_topics_with_a_clock(bag, tmp_path):
    played = _replay_and_record(bag, tmp_path / "replay", ["--topics", "/joint_states", "/rabbit/markers",
                                                           "--clock", "100", "--rate", "2"],
                                ["--topics", "/joint_states", "/rabbit/markers", "/clock"])
    assert played.returncode == 0, played.stderr
    original, replayed = _messages(bag), _messages(tmp_path / "replay")
    assert set(replayed) == {"/joint_states", "/rabbit/markers", "/clock"}
    assert len(replayed["/joint_states"]) == len(original["/joint_states"])
    assert len(replayed["/rabbit/markers"]) == len(original["/rabbit/markers"])
    # /clock from the log time at 100 Hz over the bag's span (not the bag's 1 kHz /clock); the
    # span is wall time of the recording (receive log times), so the count comes from the bag
    from rosbags.rosbag2 import Reader

    from rabbit_sim.player import clock_times

    with Reader(bag) as reader:
        expected = len(list(clock_times(reader.start_time, reader.end_time, 100.0)))
    assert len(replayed["/clock"]) == expected


@pytest.mark.parametrize("args, message", [
    (["/nonexistent"], "error: /nonexistent is not a rosbag2 bag directory (no metadata.yaml)"),
    (["BAG", "--topics", "/nope"], "error: not in BAG: /nope"),
    (["BAG", "--rate", "0"], "play.py: error: --rate must be > 0, --clock, --delay and --wait-for-subscribers >= 0"),
])
def test_bad_input_is_one_line(bag, args, message):
    args = [str(bag) if a == "BAG" else a for a in args]
    result = subprocess.run([sys.executable, "scripts/play.py", *args, "--delay", "0"], cwd=ROOT,
                            capture_output=True, text=True, timeout=120, env=dict(os.environ))
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1
    assert result.stderr.strip().startswith(message.replace("BAG", str(bag)))
