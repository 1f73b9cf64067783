"""A keyed controller's check of /joint_states (rabbit_msgs_py.pairing.SignedStates): signed
with the key and its placement count, one simulator instance, in (placement, stamp) order."""

from __future__ import annotations

import pytest

from rabbit_msgs_py.pairing import BATCH_SWITCH_AFTER, PairingKey, SignedStates, new_key

from fake_clock import FakeClock

pytestmark = pytest.mark.unit

Q, DQ = [0.0, 0.75, 0.1, 0.2, 0.3, 0.2, 0.3], [1.0] + [0.0] * 6
MS = 1_000_000


def test_states_are_taken_in_placement_and_stamp_order_and_a_replay_is_refused():
    key, clock = PairingKey.parse(new_key()), FakeClock()
    states = SignedStates(key, clock)
    sign = lambda placement, stamp, source="sim/a": key.sign_state(source, placement, stamp, Q, DQ)  # noqa: E731
    assert states.check(sign(1, 0), 0, Q, DQ) == 1
    assert states.check(sign(1, 5 * MS), 5 * MS, Q, DQ) == 1
    assert states.check(sign(1, 5 * MS), 5 * MS, Q, DQ) == 1  # the same state again: a lockstep re-send
    with pytest.raises(ValueError, match="a replay"):
        states.check(sign(1, 2 * MS), 2 * MS, Q, DQ)
    assert states.check(sign(2, 0), 0, Q, DQ) == 2  # placed again (a reset): its stamps start over
    with pytest.raises(ValueError, match="a replay"):
        states.check(sign(1, 9 * MS), 9 * MS, Q, DQ)  # a state of the placement before
    with pytest.raises(ValueError, match="not signed"):
        states.check(sign(3, 0), 1, Q, DQ)  # the stamp changed since it was signed
    with pytest.raises(ValueError, match="not signed"):
        states.check(PairingKey.parse(new_key()).sign_state("sim/a", 3, 0, Q, DQ), 0, Q, DQ)
    with pytest.raises(ValueError, match="not signed"):
        states.check("sim/a", 0, Q, DQ)  # no signature at all
    with pytest.raises(ValueError, match="while sim/a runs"):
        states.check(sign(1, 0, "sim/b"), 0, Q, DQ)
    clock.now += BATCH_SWITCH_AFTER  # sim/a silent: a simulator restarted by hand is followed
    assert states.check(sign(1, 0, "sim/b"), 0, Q, DQ) == 1 and states.source == "sim/b"
