"""The user's own pairing key (rabbit_msgs_py.pairing.user_key, resolve_key): made on first use
with owner-only permissions, shared by every node that starts without a key, refused when
others may read it."""

from __future__ import annotations

import os
import stat
import threading

import pytest

from rabbit_msgs_py.pairing import NO_KEY, PairingKey, new_key, resolve_key, user_key, user_key_file

pytestmark = pytest.mark.unit


def test_the_key_file_lives_under_ros_home_or_dot_ros():
    assert user_key_file({"ROS_HOME": "/x/ros"}) == user_key_file({"ROS_HOME": "/x/ros/"})
    assert str(user_key_file({"ROS_HOME": "/x/ros"})) == "/x/ros/rabbit_hzd/pairing_key"
    assert user_key_file({}).parts[-3:] == (".ros", "rabbit_hzd", "pairing_key")


def test_the_first_node_makes_the_key_owner_only_and_the_next_reads_the_same(tmp_path):
    path = tmp_path / "home" / "rabbit_hzd" / "pairing_key"
    first = user_key(path)
    assert stat.S_IMODE(path.stat().st_mode) == 0o600 and stat.S_IMODE(path.parent.stat().st_mode) == 0o700
    assert user_key(path) == first and isinstance(first, PairingKey)
    assert sorted(p.name for p in path.parent.iterdir()) == ["pairing_key"]  # no temporary file left


def test_nodes_starting_at_once_share_one_key(tmp_path):
    path = tmp_path / "rabbit_hzd" / "pairing_key"
    keys: list[PairingKey] = []
    threads = [threading.Thread(target=lambda: keys.append(user_key(path))) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(keys) == 8 and len(set(keys)) == 1


def test_a_key_file_others_can_read_or_that_is_no_key_is_refused_with_one_line(tmp_path):
    path = tmp_path / "pairing_key"
    path.write_text(new_key() + "\n")
    os.chmod(path, 0o644)
    with pytest.raises(ValueError, match=r"open to others \(mode 0644\): chmod 600"):
        user_key(path)
    os.chmod(path, 0o600)
    user_key(path)
    path.write_text("short\n")
    with pytest.raises(ValueError, match="pairing_key must be 16 to 64 characters"):
        user_key(path)


def test_the_parameter_resolves_to_the_users_key_an_explicit_one_or_none(tmp_path):
    environ = {"ROS_HOME": str(tmp_path)}
    key, source = resolve_key("", environ)
    assert key == user_key(tmp_path / "rabbit_hzd" / "pairing_key") and str(tmp_path) in source
    given = new_key()
    assert resolve_key(given, environ)[0] == PairingKey.parse(given)
    key, source = resolve_key(NO_KEY, environ)
    assert key is None and "NO pairing key" in source
    with pytest.raises(ValueError, match="16 to 64"):
        resolve_key("tooshort", environ)
