"""The simulator's state batches (``/sim/state_batch``): when one goes out
(:class:`rabbit_sim.stepping.batch.StateBatcher`, ROS-free) and what a message holds
(``rabbit_msgs_py.conversions``)."""

from __future__ import annotations

import array
import math

import pytest

from rabbit_msgs_py.conversions import BATCH_FIELDS, MessageError, state_batch_from_msg, state_batch_to_msg
from rabbit_sim.stepping.batch import StateBatcher

pytestmark = pytest.mark.unit

MS = 1_000_000
POS, VEL, EFF = [0.1] * 7, [1.0] * 7, [2.0] * 7


def sent_at(batcher: StateBatcher, stamps: list[int]) -> list[int]:
    """The stamps (ms) whose state made the batch go out."""
    return [s // MS for s in stamps if batcher.add(s, POS, VEL, EFF) and batcher.take()]


def test_a_batch_goes_out_on_its_grid_and_on_every_state_the_policy_decides_on():
    batcher = StateBatcher(20)
    assert sent_at(batcher, [0]) == [0]  # the placed state at once
    assert sent_at(batcher, [k * MS for k in range(1, 61)]) == [20, 40, 60]
    batcher.follow_decisions(7)  # a policy deciding every 7 ticks: its states are not held back
    assert sent_at(batcher, [k * MS for k in range(61, 101)]) == [63, 70, 77, 80, 84, 91, 98, 100]
    batcher.follow_decisions(0)  # once per step: only the grid
    assert sent_at(batcher, [k * MS for k in range(101, 141)]) == [120, 140]


def test_a_state_sent_again_or_placed_goes_out_at_once_and_every_state_is_kept_in_order():
    batcher = StateBatcher(20)
    sent_at(batcher, [0, MS, 2 * MS])
    assert batcher.add(2 * MS, POS, VEL, EFF)  # re-sent (lockstep waits for a reply): nobody waits for more
    rows, count = batcher.take()
    assert count == 3 and list(rows[::BATCH_FIELDS]) == [MS, 2 * MS, 2 * MS]
    assert batcher.add(0, POS, VEL, EFF)  # placed again
    assert batcher.take()[1] == 1 and batcher.count == 0


def test_one_tick_batches_are_every_state_on_its_own():
    batcher = StateBatcher(1)
    assert sent_at(batcher, [k * MS for k in range(5)]) == [0, 1, 2, 3, 4]
    with pytest.raises(ValueError, match="whole number >= 1"):
        StateBatcher(0)


def test_a_batch_message_round_trips_and_a_malformed_one_is_refused_in_one_line():
    rows = array.array("d", [5 * MS] + list(range(21)) + [6 * MS] + list(range(21, 42)))
    states = state_batch_from_msg(state_batch_to_msg(rows, 2))
    assert [s.stamp for s in states] == [5 * MS, 6 * MS]
    assert list(states[1].position) == list(range(21, 28)) and list(states[1].effort) == list(range(35, 42))
    bad = state_batch_to_msg(rows, 2)
    bad.data = rows[:-1]
    with pytest.raises(MessageError, match="n x 22"):
        state_batch_from_msg(bad)
    for value, why in ((math.nan, "NaN"), (0.5, "whole number of ns"), (-MS, "whole number of ns")):
        broken = array.array("d", rows)
        broken[0 if why != "NaN" else 3] = value
        with pytest.raises(MessageError, match=why):
            state_batch_from_msg(state_batch_to_msg(broken, 2))


def test_a_malformed_batch_gives_no_state_and_one_line():
    """Observers subscribe raw: a batch is read from its bytes, and a refused one (bad
    layout, not a Float64MultiArray, NaN) gives no state and one line."""
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Float64MultiArray

    from rabbit_msgs_py.conversions import batch_states_or_log

    lines: list[str] = []
    good = serialize_message(state_batch_to_msg(array.array("d", [MS] + [0.0] * 21), 1))
    assert [s.stamp for s in batch_states_or_log(good, "/sim/state_batch", lines.append)] == [MS] and lines == []
    bad = serialize_message(state_batch_to_msg(array.array("d", [MS] + [0.0] * 20), 1))
    assert batch_states_or_log(bad, "/sim/state_batch", lines.append) == []
    assert len(lines) == 1 and lines[0].startswith("ignoring /sim/state_batch: a state batch is n x 22")
    flood = serialize_message(Float64MultiArray(data=[math.nan] * 30))  # the hostile suite's flood
    nan = serialize_message(state_batch_to_msg(array.array("d", [MS] + [math.nan] * 21), 1))
    for refused, why in ((flood, "not a state batch"), (b"\x00\x01\x00\x00\xff", "not a state batch"),
                         (good[:-9], "do not fill"), (nan, "NaN")):
        assert batch_states_or_log(refused, "/sim/state_batch", lines.append) == []
        assert why in lines[-1]


def test_a_signed_batch_is_verified_on_its_bytes_before_its_values_are_read():
    from rclpy.serialization import serialize_message

    from rabbit_msgs_py.conversions import batch_states_or_log
    from rabbit_msgs_py.pairing import PairingKey, new_key

    key, other = PairingKey.parse(new_key()), PairingKey.parse(new_key())
    rows = array.array("d", [MS] + [0.5] * 21)
    checked: list[tuple[str, bytes]] = []

    def verify(label: str, data: bytes) -> None:
        checked.append((label, data))
        key.verify_batch(label, data)

    lines: list[str] = []
    signed = serialize_message(state_batch_to_msg(rows, 1, key.batch_label("sim/a", 1, rows.tobytes())))
    assert [s.stamp for s in batch_states_or_log(signed, "/sim/state_batch", lines.append, verify)] == [MS]
    assert checked[-1][1] == rows.tobytes() and lines == []
    forged = serialize_message(state_batch_to_msg(rows, 1, other.batch_label("sim/a", 1, rows.tobytes())))
    nan = array.array("d", [MS] + [math.nan] * 21)  # signed with another key: refused before its NaN is read
    forged_nan = serialize_message(state_batch_to_msg(nan, 1, other.batch_label("sim/a", 2, nan.tobytes())))
    for refused in (forged, forged_nan):
        assert batch_states_or_log(refused, "/sim/state_batch", lines.append, verify) == []
        assert "not signed with this stack's pairing key" in lines[-1]
