"""Recording to rosbag2/MCAP: a recorded in-process run reopened with a reader that is not
the writer's code path (``mcap`` + ``mcap-ros2-support``), nothing lost, metadata.yaml
consistent; overwrite protection and path errors; clean close on SIGTERM; plots."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from collections import Counter, defaultdict
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from rabbit_msgs_py import topics as topic_names
from rabbit_msgs_py.catalog import STACK_TOPICS
from rabbit_msgs_py.decision_ticks import PER_STEP
from rabbit_msgs_py.node_runner import NodeStartError
from rabbit_policy.bringup.config import StackConfig
from rabbit_policy.bringup.in_process import run_in_process
from rabbit_policy.experiment.scenario import Push
from rabbit_sim.bag import BagError, BagWriter, QosSpec, is_bag_directory

RECORDED = {topic_names.resolve(name): spec for name, spec in STACK_TOPICS.items()}  # a root-namespace stack's

pytestmark = [pytest.mark.ros, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module", params=["none", "zstd"])
def recorded(request, tmp_path_factory):
    bag = tmp_path_factory.mktemp("bags") / f"run_{request.param}"
    duration = 8.0 if request.param == "none" else 3.0
    pushes = (Push(1.0, 40.0, 0.1),) if request.param == "zstd" else ()  # the short run is pushed once
    # decisions once per step: every gait is then decided on a state the recorder is waited
    # for; with decisions every N ticks one can fall on the very last state, after the
    # recording stopped (docs/recording.md)
    config = StackConfig(duration=duration, schedule=((0.0, 0.9), (duration / 2, 1.1)), record=str(bag),
                         record_compression=request.param, pushes=pushes, decision=PER_STEP)
    report, nodes = run_in_process(config)
    assert report.completed and not report.fell
    return bag, nodes, request.param


def _read_all(bag: Path):
    (mcap_file,) = bag.glob("*.mcap")
    with mcap_file.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        summary = reader.get_summary()
        messages = [(channel.topic, message.log_time, decoded, schema.name)
                    for schema, channel, message, decoded in reader.iter_decoded_messages()]
    return header, summary, messages


def test_bag_holds_every_message_the_stack_published(recorded):
    bag, nodes, compression = recorded
    header, summary, messages = _read_all(bag)
    assert header.profile == "ros2"
    assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
    assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}
    assert all("reliability" in c.metadata["offered_qos_profiles"] for c in summary.channels.values())
    counts = Counter(topic for topic, *_ in messages)
    # nothing lost, nothing twice: every state simulated once (a state sent again is written
    # once), every reply the controller sent (computed, or repeated for a state sent again)
    sim, controller = nodes["sim_node"], nodes["hzd_controller_node"]
    assert counts["/joint_states"] == sim.ticks + 1 == counts["/hip_velocity"]  # (the recorder listens to it)
    assert counts["/clock"] == sim.ticks // 10 + 1  # clock_rate 100 Hz: the states on the 10 ms grid
    batched = [round(v) for topic, _t, msg, _s in messages if topic == "/sim/state_batch" for v in msg.data[::22]]
    assert sorted(set(batched)) == [k * 1_000_000 for k in range(sim.ticks + 1)]  # every state, in order
    assert batched == sorted(batched) and len(batched) == sim.ticks + 1 + sim.resends
    assert counts["/joint_torques"] == controller.torques_published + controller.replies_repeated
    assert counts["/push_applied"] == (2 if compression == "zstd" else 0)  # start and end of the push
    assert counts["/hzd/alpha"] == nodes["policy_node"].decisions
    # the phase goes out while anyone subscribes: recorded from when the controller saw the recorder
    assert 0 < counts["/hzd/phase"] <= controller.torques_published
    assert counts["/cmd_speed"] == 2 and counts["/fallen"] >= 1
    # types as documented, timestamps monotonic per topic
    types = {topic: schema for topic, _t, _m, schema in messages}
    for topic, schema in types.items():
        assert schema == RECORDED[topic].type_name
    last = defaultdict(int)
    for topic, log_time, _msg, _schema in messages:
        assert log_time >= last[topic]
        last[topic] = log_time
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
              for topic, _t, m, _s in messages if topic == "/joint_states"]
    assert all(b >= a for a, b in zip(stamps, stamps[1:]))
    if compression == "zstd":
        assert {c.compression for c in summary.chunk_indexes} == {"zstd"}


def test_metadata_yaml_matches_the_mcap(recorded):
    bag, _nodes, _compression = recorded
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["ros_distro"] == "jazzy"
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap"
    _header, _summary, messages = _read_all(bag)
    counts = Counter(topic for topic, *_ in messages)
    listed = {t["topic_metadata"]["name"]: t for t in meta["topics_with_message_count"]}
    assert set(listed) == set(RECORDED)
    for topic, entry in listed.items():
        assert entry["message_count"] == counts[topic]
        assert entry["topic_metadata"]["type"] == RECORDED[topic].type_name
        assert entry["topic_metadata"]["serialization_format"] == "cdr"
        assert entry["topic_metadata"]["offered_qos_profiles"]
    assert meta["message_count"] == len(messages)
    assert meta["relative_file_paths"] == [p.name for p in bag.glob("*.mcap")]


def test_plot_run_writes_the_figures(recorded, tmp_path):
    bag, _nodes, _compression = recorded  # both bags: the reader handles zstd chunks too
    result = subprocess.run([sys.executable, str(ROOT / "scripts" / "plot_run.py"), str(bag)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert is_bag_directory(bag)  # the figures go beside it: the bag can still be overwritten
    for name in ("speed.png", "joints.png", "limit_cycle.png", "pitch.png"):
        png = bag.parent / f"{bag.name}_plots" / name
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000
    import importlib

    plot_run = importlib.import_module("rabbit_sim.commands.plot_run")
    run = plot_run.read_run(bag)
    intervals = plot_run.push_intervals(run["push"], float(run["t"][-1]))
    assert intervals == ([(1.0, pytest.approx(1.1), 40.0)] if _compression == "zstd" else [])


def test_existing_or_impossible_outputs_are_refused(tmp_path):
    qos = QosSpec(True, False, 10)
    bag = tmp_path / "bag"
    BagWriter(bag).close()
    with pytest.raises(BagError, match="exists"):
        BagWriter(bag)
    writer = BagWriter(bag, overwrite=True)  # replaces it
    writer.add_topic("/cmd_speed", "std_msgs/msg/Float64", qos)
    writer.close()
    precious = tmp_path / "thesis"
    precious.mkdir()
    (precious / "chapter1.tex").write_text("years of work")
    for not_a_bag in (precious, tmp_path / "thesis" / "chapter1.tex"):
        with pytest.raises(BagError, match="not a bag directory"):
            BagWriter(not_a_bag, overwrite=True)
    assert (precious / "chapter1.tex").read_text() == "years of work"
    BagWriter(tmp_path / "missing" / "parents" / "bag").close()  # its parent directories are made
    assert is_bag_directory(tmp_path / "missing" / "parents" / "bag")
    with pytest.raises(BagError, match="cannot create"):
        BagWriter(tmp_path / "thesis" / "chapter1.tex" / "bag")  # a parent that is a file
    with pytest.raises(BagError):
        BagWriter("/proc/rabbit_bag")  # not writable
    import rclpy

    from rabbit_sim.recorder_node import RecorderNode

    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        with pytest.raises(NodeStartError, match="exists"):
            RecorderNode(context=context, output=str(bag))
        with pytest.raises(NodeStartError, match="unknown topics"):
            RecorderNode(context=context, output=str(tmp_path / "b2"), topics=["/nope"])
    finally:
        rclpy.shutdown(context=context)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_record_script_closes_the_bag_on_a_signal(tmp_path, sig):
    bag = tmp_path / "idle"
    proc = subprocess.Popen([sys.executable, str(ROOT / "scripts" / "record.py"), str(bag)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 30
    while not any(bag.glob("*.mcap")) and time.monotonic() < deadline:
        time.sleep(0.1)
    time.sleep(1.0)
    proc.send_signal(sig)
    _out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert "closed" in err
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())
    assert meta["rosbag2_bagfile_information"]["version"] == 9
    _header, summary, messages = _read_all(bag)  # a complete, readable MCAP (summary written)
    assert summary is not None and messages == []


def test_a_recording_that_fails_fails_the_run(tmp_path):
    """A bag that cannot be written (here: the file-size limit, as a full disk would) is a
    failed run: exit status 3 and the error in the JSON, not "error": null."""
    import json
    import subprocess
    import sys

    limit = 300_000  # bytes: the bag outgrows it within a second of simulation
    code = ("import resource, runpy, signal, sys; signal.signal(signal.SIGXFSZ, signal.SIG_IGN); "
            f"resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit})); "
            f"sys.argv = ['run_stack.py', '--duration', '1.5', '--record', {str(tmp_path / 'bag')!r}, '--json']; "
            f"runpy.run_path({str(ROOT / 'scripts' / 'run_stack.py')!r}, run_name='__main__')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=180)
    assert out.returncode == 3, out.stderr[-2000:]
    report = json.loads(out.stdout.strip().splitlines()[-1])  # Fast DDS may print above it: the limit hits its SHM files
    assert report["error"].startswith("recording failed") and report["completed"] is False
    assert "File too large" in report["error"] or "status" in report["error"], report["error"]


def test_run_stack_refuses_to_overwrite_what_is_not_a_bag(tmp_path):
    import subprocess
    import sys

    (tmp_path / "notes.txt").write_text("keep me")
    out = subprocess.run([sys.executable, str(ROOT / "scripts" / "run_stack.py"), "--record", str(tmp_path),
                          "--overwrite"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "not a bag directory" in out.stderr
    assert (tmp_path / "notes.txt").read_text() == "keep me"


def test_a_bag_cut_short_is_recovered(tmp_path):
    """A recorder killed mid-run leaves an MCAP without summary or metadata.yaml; `record.py
    --recover` rebuilds a bag that rosbags and mcap read, holding every whole chunk."""
    import subprocess
    import sys

    from mcap.reader import make_reader
    from rosbags.rosbag2 import Reader

    bag = tmp_path / "cut"
    writer_code = (
        "import os; from rabbit_sim.bag import BagWriter, QosSpec; "
        f"w = BagWriter({str(bag)!r}); w.add_topic('/cmd_speed', 'std_msgs/msg/Float64', QosSpec(True, False, 10)); "
        "[w.write('/cmd_speed', 1_000_000 * i, bytes(4) + (float(i)).hex().encode()[:8]) for i in range(60000)]; "
        "os._exit(0)"  # no close: as if killed
    )
    subprocess.run([sys.executable, "-c", writer_code], check=True, timeout=120)
    assert not (bag / "metadata.yaml").exists()
    with pytest.raises(Exception):
        with Reader(bag):
            pass
    out = subprocess.run([sys.executable, str(ROOT / "scripts" / "record.py"), str(bag), "--recover"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    recovered = tmp_path / "cut.recovered"
    with Reader(recovered) as reader:
        count = sum(1 for _ in reader.messages())
    assert 40000 < count < 60000  # all but the chunk in progress (1 MiB of ~20-byte records here)
    with (recovered / "cut.recovered.mcap").open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and sum(summary.statistics.channel_message_counts.values()) == count
    again = subprocess.run([sys.executable, str(ROOT / "scripts" / "record.py"), str(tmp_path / "nothing"),
                            "--recover"], capture_output=True, text=True, timeout=60)
    assert again.returncode == 1 and "no MCAP file" in again.stderr


def test_lockstep_recording_loses_nothing_on_a_loaded_machine(tmp_path):
    """Both cores busy with other work: the lockstep stack (three node processes and the
    recorder) still records every state, every torque and every clock tick, because the
    simulator waits for the recorder as it waits for the controller."""
    import subprocess
    import sys

    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        out = subprocess.run([sys.executable, str(ROOT / "scripts" / "run_stack.py"), "--duration", "3",
                              "--record", str(tmp_path / "bag"), "--json"],
                             capture_output=True, text=True, timeout=300)
    finally:
        for hog in hogs:
            hog.kill()
    assert out.returncode == 0, out.stderr[-2000:]
    typestore = get_typestore(Stores.ROS2_JAZZY)
    ticks: dict[str, set[int]] = {"/joint_states": set(), "/hip_velocity": set(), "/clock": set()}
    counts: dict[str, int] = {}
    with Reader(tmp_path / "bag") as reader:
        for connection, _t, raw in reader.messages():
            counts[connection.topic] = counts.get(connection.topic, 0) + 1
            if connection.topic in ticks:
                msg = typestore.deserialize_cdr(raw, connection.msgtype)
                stamp = msg.clock if connection.topic == "/clock" else msg.header.stamp
                ticks[connection.topic].add(round((stamp.sec * 1_000_000_000 + stamp.nanosec) / 1e6))  # ms
    # every tick on every stream, once (a state sent again is written once); /clock at 100 Hz
    for topic, seen in ticks.items():
        grid = set(range(0, 3001, 10 if topic == "/clock" else 1))
        assert seen == grid, f"{topic} misses ticks {sorted(grid - seen)[:10]}"
        assert counts[topic] == len(grid), f"{topic}: {counts[topic]} messages for {len(grid)} ticks"
    assert counts["/joint_torques"] >= 3000


def _stamps_ms(bag: Path, topic: str) -> list[int]:
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    typestore = get_typestore(Stores.ROS2_JAZZY)
    with Reader(bag) as reader:
        connections = [c for c in reader.connections if c.topic == topic]
        msgs = (typestore.deserialize_cdr(raw, c.msgtype) for c, _t, raw in reader.messages(connections))
        stamps = (m.clock if topic == "/clock" else m.header.stamp for m in msgs)
        return [round((stamp.sec * 1_000_000_000 + stamp.nanosec) / 1e6) for stamp in stamps]


def test_a_recorder_that_connects_late_never_wedges_lockstep(tmp_path):
    """The issue's freeze, provoked directly: sim_node waits for a recorder (re-sending the
    first state every 50 ms, ~30 times) that starts 1.5 s late, in a context of its own
    standing in for its own process. The run goes on once it connects, and the bag holds
    every tick exactly once."""
    import sys as _sys

    _sys.path.insert(0, str(ROOT / "tests"))
    from ros_helpers import ros_context, spin_for, spin_until

    from rabbit_hzd_controller.hzd_controller_node import HZDControllerNode
    from rabbit_policy.policy_node import PolicyNode
    from rabbit_sim.recorder_node import RecorderNode
    from rabbit_sim.sim_node import SimNode

    bag = tmp_path / "late"
    with ros_context() as (context, executor):
        nodes = [PolicyNode(context=context), HZDControllerNode(context=context),
                 SimNode(context=context, wait_for_recorder=True)]
        for node in nodes:
            executor.add_node(node)
        sim = nodes[2]
        spin_for(executor, 1.5)
        assert sim.time == 0.0 and sim.states_published >= 10  # held at t = 0, re-sending
        with ros_context() as (ctx_r, ex_r):
            recorder = RecorderNode(context=ctx_r, output=str(bag), topics=["/joint_states", "/hip_velocity"])
            ex_r.add_node(recorder)
            assert spin_until((executor, ex_r), lambda: sim.time >= 0.5, timeout=60.0), f"wedged at {sim.time}"
            sim_end = round(sim.time * 1000)
            spin_until((executor, ex_r), lambda: recorder.counts.get("/joint_states", 0) > sim_end, timeout=10.0)
            recorder.close()
    for topic in ("/joint_states", "/hip_velocity"):
        stamps = _stamps_ms(bag, topic)
        assert len(stamps) >= sim_end and stamps == list(range(len(stamps))), f"{topic}: {stamps[:10]}..."
    from rabbit_sim.bag import joint_state_stamps  # bench_stack's count of the states a bag holds

    assert sorted(joint_state_stamps(bag)) == [ms * 1_000_000 for ms in _stamps_ms(bag, "/joint_states")]


def test_a_recorder_that_stops_fails_the_run_within_a_bounded_time(tmp_path):
    """The recorder process is frozen (SIGSTOP) mid-run: lockstep waits for it (it never steps
    past a recording it cannot keep), and run_stack fails with one line naming the
    recorder within ``--recorder-timeout``, then stops every node, the frozen one included.
    Frozen before it wrote anything (as a recorder slow to start on a busy machine), for
    longer than that timeout, it is waited for: the run goes on once it resumes."""
    import os
    import subprocess
    import sys

    timeout = 3.0  # s: --recorder-timeout (default 10)
    bag = tmp_path / "frozen"
    started = time.monotonic()
    proc = subprocess.Popen([sys.executable, str(ROOT / "scripts" / "run_stack.py"), "--duration", "60",
                             "--record", str(bag), "--recorder-timeout", str(timeout)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        recorder = None
        while recorder is None and time.monotonic() - started < 60:
            time.sleep(0.2)
            for pid in filter(str.isdigit, os.listdir("/proc")):
                try:
                    cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace")
                except OSError:
                    continue
                if "rabbit_sim.recorder_node" in cmdline and str(bag) in cmdline:
                    recorder = int(pid)
        assert recorder is not None
        os.kill(recorder, signal.SIGSTOP)  # late to start: waited for, longer than the timeout
        time.sleep(timeout + 2.0)
        os.kill(recorder, signal.SIGCONT)
        deadline = time.monotonic() + 60
        while not list(bag.glob("*.mcap")) or list(bag.glob("*.mcap"))[0].stat().st_size < 200_000:
            assert time.monotonic() < deadline and proc.poll() is None, proc.communicate()[0] if proc.poll() is not None else "bag did not grow"
            time.sleep(0.1)
        os.kill(recorder, signal.SIGSTOP)
        frozen_at = time.monotonic()
        out, err = proc.communicate(timeout=timeout + 60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 3, err[-2000:]
    assert "the recorder stopped" in out
    assert time.monotonic() - frozen_at < timeout + 30
    assert not Path(f"/proc/{recorder}").exists() or "zombie" in Path(f"/proc/{recorder}/status").read_text()


def test_header_stamp_reads_the_stamp_from_cdr_bytes():
    """The recorder's ``/recorder/recorded_until`` comes from the serialized state's bytes."""
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState

    from rabbit_sim.recorder_node import header_stamp

    msg = JointState()
    msg.header.stamp.sec, msg.header.stamp.nanosec = 12, 345_000_000
    msg.position = [0.1, 0.2]
    assert header_stamp(serialize_message(msg)) == (12, 345_000_000)


def test_a_recorder_started_by_hand_beside_a_walking_stack_loses_nothing_and_stops_at_once(tmp_path):
    """A stack walks in lockstep without wait_for_recorder (started by hand); a recorder
    starts beside it in a context of its own (its process), then stalls for 0.5 s as a busy
    machine stalls it. Once, the simulation ran on and overwrote states the recorder had not
    taken (4.3 % of /joint_states lost, gaps up to 387 ms) and its Ctrl-C took 10.5-11.5 s,
    recording on. The simulation follows it from its announcement: every state from the
    first it wrote is in the bag; on a stop (run_node's drain) it writes what it received
    and ends within a second; once it is gone the simulation steps freely again."""
    import sys as _sys

    _sys.path.insert(0, str(ROOT / "tests"))
    from ros_helpers import ros_context, spin_for, spin_until

    from rabbit_hzd_controller.hzd_controller_node import HZDControllerNode
    from rabbit_msgs_py.node_runner import drain
    from rabbit_policy.policy_node import PolicyNode
    from rabbit_sim.recorder_node import RecorderNode
    from rabbit_sim.sim_node import SimNode

    bag = tmp_path / "by_hand"
    with ros_context() as (context, executor):
        nodes = [PolicyNode(context=context), HZDControllerNode(context=context), SimNode(context=context)]
        for node in nodes:
            executor.add_node(node)
        sim = nodes[2]
        assert spin_until(executor, lambda: sim.time >= 0.3, timeout=60.0)
        with ros_context() as (ctx_r, ex_r):
            recorder = RecorderNode(context=ctx_r, output=str(bag), topics=["/joint_states"])
            ex_r.add_node(recorder)
            written = lambda: recorder.counts.get("/joint_states", 0)  # noqa: E731
            assert spin_until((executor, ex_r), lambda: written() > 200, timeout=60.0)
            stalled_at = sim.time
            spin_for(executor, 0.5)  # the recorder's process gets no CPU: the simulation must wait for it
            assert sim.time - stalled_at < 0.02, (stalled_at, sim.time)
            assert spin_until((executor, ex_r), lambda: written() > 600, timeout=60.0)
            start = time.monotonic()
            drain(ex_r, recorder, ctx_r)  # as after Ctrl-C (run_node), the stack still walking
            stop_took = time.monotonic() - start
            recorder.close()
            last_written = written()
        held_at = sim.time
        assert spin_until(executor, lambda: sim.time >= held_at + 0.3, timeout=60.0), "held for a recorder gone"
    stamps = _stamps_ms(bag, "/joint_states")
    assert len(stamps) == last_written and stamps == list(range(stamps[0], stamps[0] + len(stamps))), stamps[:5]
    assert stop_took < 1.0, stop_took
