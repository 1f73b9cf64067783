"""Explicit pairing of a simulator with its controller: signed torque replies.

A stack (run_stack) makes a random key and gives it to ``sim_node`` and
``hzd_controller_node`` (parameter ``pairing_key``; each node reads it once at start and then
removes the parameter, so ``ros2 param get`` cannot read it). Nodes started by hand without
one pair with the user's own key, ``$ROS_HOME/rabbit_hzd/pairing_key`` (``~/.ros`` without
``ROS_HOME``), made on first use and readable by its owner only, as OpenSSH keeps a private
key; ``pairing_key:=none`` pairs with no key (unsafe: any node on the graph can then drive the
robot). The controller signs every
torque reply: its ``header.frame_id`` is ``<instance id>#<tag>``, the tag a keyed BLAKE2b
MAC (64 bits) of the stamp it answers (ns) and its four torques (N m, as float64). The
simulator applies only replies whose tag checks with its key. A node without the key cannot
make a tag for a new stamp or new torques, even after seeing every earlier reply: replaying
a seen reply repeats the real controller's torques for a stamp no longer due (ignored).

run_stack hands its key to the node processes it starts in a file (``pairing_key_file``,
owner read/write only, in a directory of its own, removed at exit), never on a command line
or in the environment, which other users can read (``/proc/PID/cmdline``).

This guards the robot against other nodes on the ROS graph (a second controller, a test
script, a node that answers every state) that do not have the key: another user's process, or
a node of this user's that does not read the key file. It is not SROS2: root, and any process
of the same user, can read the key file (and a process's memory).
"""

from __future__ import annotations

import hashlib
import hmac
import os
import secrets
import stat
import struct
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping, Sequence

from .decision_ticks import SIGNATURE_FIELD

TAG_SEPARATOR = "#"
BATCH_LABEL = "state"
"""The first dimension's label of a ``/sim/state_batch`` (``conversions.BATCH_DIMENSIONS``)."""
MIN_KEY_CHARS = 16
MAX_KEY_BYTES = 64  # BLAKE2b's longest key
NO_KEY = "none"
UNSIGNED_GAIT = "the gait is not signed (its policy runs without this stack's pairing key)"
"""Why a gait without a signature is refused (:meth:`PairingKey.verify_gait`)."""
"""``pairing_key:=none``: pair with no key (unsafe: any node on the graph can drive the robot)."""
KEY_FILE_HELP = ("read the pairing key from this file (owner read/write only; how run_stack hands its key to the "
                 "node processes it starts, never on a command line); '' = use pairing_key")
"""The ``pairing_key_file`` parameter's description, the same on every node."""
USER_KEY_FILE = Path("rabbit_hzd") / "pairing_key"
"""The user's own key, under ROS's home directory (:func:`user_key_file`)."""


def new_key() -> str:
    """A fresh random key for one stack: ``pair-`` and 32 hex digits (the prefix keeps a
    command line's ``-p pairing_key:=...`` from ever reading it as a number)."""
    return "pair-" + secrets.token_hex(16)


@dataclass(frozen=True)
class PairingKey:
    """The key one stack's simulator and controller share (bytes of the parameter's text)."""

    secret: bytes

    @classmethod
    def parse(cls, text: str) -> "PairingKey | None":
        """The ``pairing_key`` parameter: ``""`` = none (no pairing by key); otherwise at
        least 16 characters and at most 64 bytes (UTF-8), else ``ValueError``."""
        if not text:
            return None
        secret = text.encode()
        if len(text) < MIN_KEY_CHARS or len(secret) > MAX_KEY_BYTES:
            raise ValueError(f"pairing_key must be {MIN_KEY_CHARS} to {MAX_KEY_BYTES} characters (run_stack makes one), "
                             f"got {len(text)}")
        return cls(secret)

    def tag(self, stamp: int, torques: Sequence[float]) -> str:
        """16 hex digits: the MAC of ``stamp`` (ns) and the torques (N m)."""
        payload = struct.pack(f"<q{len(torques)}d", stamp, *torques)
        return hashlib.blake2b(payload, key=self.secret, digest_size=8).hexdigest()

    def sign(self, source: str, stamp: int, torques: Sequence[float]) -> str:
        """The ``frame_id`` of a signed reply from controller instance ``source``."""
        return f"{source}{TAG_SEPARATOR}{self.tag(stamp, torques)}"

    def gait_signature(self, source: str, count: int, alpha: Sequence[float], kd: float) -> str:
        """A gait's signature, ``<source> <count> <kd> <tag>``: policy instance ``source``'s
        ``count``-th gait (counting from 1), its Kd (N m s/rad, as Python writes the float)
        and the MAC of all three with the 24 coefficients (rad)."""
        return f"{source} {count} {float(kd)!r} {self._gait_tag(source, count, alpha, kd)}"

    def verify_gait(self, signature: str, alpha: Sequence[float]) -> tuple[str, int, float]:
        """(source, count, Kd) of a gait signed with this key; ``ValueError`` saying why not
        (unsigned, malformed, another key, or alpha changed since it was signed)."""
        if not signature:
            raise ValueError(UNSIGNED_GAIT)
        parts = signature.split(" ")
        try:
            source, count, kd, tag = parts[0], int(parts[1]), float(parts[2]), parts[3]
        except (IndexError, ValueError):
            raise ValueError("the gait's signature is malformed") from None
        if len(parts) != 4 or not hmac.compare_digest(tag, self._gait_tag(source, count, alpha, kd)):
            raise ValueError(f"the gait from {source} is not signed with this stack's pairing key")
        return source, count, kd

    def _gait_tag(self, source: str, count: int, alpha: Sequence[float], kd: float) -> str:
        payload = struct.pack(f"<q{len(alpha)}dd", count, *alpha, kd) + source.encode()
        return hashlib.blake2b(payload, key=self.secret, digest_size=8, person=b"rabbit-gait").hexdigest()

    def sign_settings(self, source: str, text: str) -> str:
        """``text`` (a ``/hzd/gait_timing`` announcement) signed by policy instance ``source``:
        ``text signed=<source>:<tag>``, the tag the MAC of both."""
        return f"{text} {SIGNATURE_FIELD}{source}:{self._settings_tag(source, text)}"

    def verify_settings(self, signed: str, what: str = "the gait timing", sender: str = "policy") -> tuple[str, str]:
        """(the instance that signed ``signed`` with this key, the text it signed);
        ``ValueError`` saying why not (unsigned, malformed, another key, or changed since).
        ``what``, ``sender``: the message and the node that signs it, for the error."""
        text, separator, field = signed.rpartition(f" {SIGNATURE_FIELD}")
        source, colon, tag = field.rpartition(":")
        if not separator or not colon or not source:
            raise ValueError(f"{what} is not signed (its {sender} runs without this stack's pairing key, or "
                             "another node sent it)")
        if not hmac.compare_digest(tag, self._settings_tag(source, text)):
            raise ValueError(f"{what} from {source} is not signed with this stack's pairing key")
        return source, text

    def batch_label(self, source: str, count: int, data: bytes) -> str:
        """The first dimension's label of the ``count``-th state batch simulator instance
        ``source`` sends, ``data`` its values (float64 bytes): ``state signed=<source>:<count>:<tag>``."""
        return f"{BATCH_LABEL} {SIGNATURE_FIELD}{source}:{count}:{self._batch_tag(source, count, data)}"

    def verify_batch(self, label: str, data: bytes) -> tuple[str, int]:
        """(simulator instance, count) of a state batch signed with this key (``label``: its
        first dimension's label, ``data``: its values as float64 bytes); ``ValueError``
        saying why not (unsigned, malformed, another key, or changed since it was signed)."""
        head, separator, field = label.partition(f" {SIGNATURE_FIELD}")
        source, _colon, rest = field.rpartition(":")
        source, colon, count = source.rpartition(":")
        if head != BATCH_LABEL or not separator or not colon or not source or not count.isdigit():
            raise ValueError("the state batch is not signed (its simulator runs without this stack's pairing key, or "
                             "another node sent it)")
        if not hmac.compare_digest(rest, self._batch_tag(source, int(count), data)):
            raise ValueError(f"the state batch from {source} is not signed with this stack's pairing key, or was "
                             "changed since")
        return source, int(count)

    def _batch_tag(self, source: str, count: int, data: bytes) -> str:
        payload = struct.pack("<q", count) + source.encode() + b"\0" + data
        return hashlib.blake2b(payload, key=self.secret, digest_size=8, person=b"rabbit-batch").hexdigest()

    def _settings_tag(self, source: str, text: str) -> str:
        payload = source.encode() + b"\0" + text.encode()
        return hashlib.blake2b(payload, key=self.secret, digest_size=8, person=b"rabbit-settings").hexdigest()

    def sign_state(self, source: str, placement: int, stamp: int, q: Sequence[float], dq: Sequence[float]) -> str:
        """The ``frame_id`` of a signed ``/joint_states`` from simulator instance ``source``,
        ``<source>#<placement>:<tag>``: the MAC of the placement count (the robot placed for the
        ``placement``-th time: 1 at the start, one more each reset), the stamp (ns), positions and
        velocities (m, rad, m/s, rad/s). A keyed controller orders states by (placement, stamp):
        an older one is a replay, a later placement a reset."""
        return f"{source}{TAG_SEPARATOR}{placement}:{self._state_tag(placement, stamp, q, dq)}"

    def verify_state(self, frame_id: str, stamp: int, q: Sequence[float],
                     dq: Sequence[float]) -> tuple[str, int] | None:
        """(simulator instance, placement count) of a state signed with this key, else None
        (unsigned, another key, or changed since it was signed)."""
        source, separator, field = frame_id.rpartition(TAG_SEPARATOR)
        placement, colon, tag = field.partition(":")
        if not (separator and colon and placement.isdigit()):
            return None
        if not hmac.compare_digest(tag, self._state_tag(int(placement), stamp, q, dq)):
            return None
        return source, int(placement)

    def _state_tag(self, placement: int, stamp: int, q: Sequence[float], dq: Sequence[float]) -> str:
        payload = struct.pack(f"<qq{len(q) + len(dq)}d", placement, stamp, *q, *dq)
        return hashlib.blake2b(payload, key=self.secret, digest_size=8, person=b"rabbit-state").hexdigest()

    def verify(self, frame_id: str, stamp: int, torques: Sequence[float]) -> str | None:
        """The instance id of a reply signed with this key, else None (unsigned, another
        key, or torques or stamp changed since it was signed)."""
        source, separator, tag = frame_id.rpartition(TAG_SEPARATOR)
        if not separator or not hmac.compare_digest(tag, self.tag(stamp, torques)):
            return None
        return source


def source_of(frame_id: str) -> str:
    """The instance id a reply names, signed or not (for log lines)."""
    return frame_id.rpartition(TAG_SEPARATOR)[0] or frame_id


def user_key_file(environ: Mapping[str, str] | None = None) -> Path:
    """The user's key file: ``$ROS_HOME/rabbit_hzd/pairing_key``, ``~/.ros/...`` without
    ``ROS_HOME`` (where rcl and ros2cli keep the user's ROS files)."""
    environ = os.environ if environ is None else environ
    home = environ.get("ROS_HOME") or str(Path.home() / ".ros")
    return Path(home) / USER_KEY_FILE


def user_key(path: Path) -> PairingKey:
    """The key in ``path``, made on first use: the file created whole (written beside it,
    then linked into place, so a node starting at the same moment reads it whole or makes
    none), owner read/write only, in a directory of the owner's. ``ValueError`` for a file
    another user owns or group or others may read or write, or one that is not a key."""
    if not path.exists():
        path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        fresh = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}")
        fd = os.open(fresh, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        try:
            with os.fdopen(fd, "w") as out:
                out.write(new_key() + "\n")
            try:
                os.link(fresh, path)
            except FileExistsError:
                pass  # another node made it first: use theirs
        finally:
            fresh.unlink()
    return _owned_key(path, "pairing key file", ": remove it and a node makes a new one")


def _owned_key(path: Path, what: str, if_empty: str = "") -> PairingKey:
    """The key in ``path``, a file of this user's that group and others cannot open;
    ``ValueError`` (one line naming ``what``) otherwise."""
    try:
        info = path.stat()
    except OSError as exc:
        raise ValueError(f"{what} {path}: {exc.strerror or exc}") from None
    if info.st_uid != os.getuid():
        raise ValueError(f"{what} {path} belongs to another user (uid {info.st_uid})")
    if stat.S_IMODE(info.st_mode) & 0o077:
        raise ValueError(f"{what} {path} is open to others (mode {stat.S_IMODE(info.st_mode):04o}): chmod 600 {path}")
    key = PairingKey.parse(path.read_text().strip())
    if key is None:
        raise ValueError(f"{what} {path} is empty{if_empty}")
    return key


def key_file(path: Path) -> PairingKey:
    """The key in an existing key file (``pairing_key_file``: run_stack writes one for its
    node processes, owner read/write only, and removes it at exit). ``ValueError`` for a file
    that is missing, another user's, open to group or others, or not a key."""
    return _owned_key(path, "pairing_key_file")


def write_key_file(path: Path, key: str) -> Path:
    """Write ``key`` to a new file ``path``, owner read/write only from its creation (the
    directory should be the owner's alone, as ``tempfile.mkdtemp`` makes one); returns it."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as out:
        out.write(key + "\n")
    return path


def resolve_key(text: str, environ: Mapping[str, str] | None = None, file: str = "") -> tuple[PairingKey | None, str]:
    """The key a node pairs with, from its ``pairing_key`` and ``pairing_key_file``
    parameters, and where it came from (for the start-up log): a ``file`` the key in it
    (:func:`key_file`; never on a command line), ``""`` the user's key (:func:`user_key`),
    ``none`` no key, else the key given (:meth:`PairingKey.parse`). ``ValueError`` with one
    line otherwise (both a key and a file included)."""
    if file:
        if text:
            raise ValueError("give pairing_key or pairing_key_file, not both")
        return key_file(Path(file)), f"signed with the pairing key in {file}"
    if text == NO_KEY:
        return None, "NO pairing key (pairing_key:=none): any node on the graph can drive the robot"
    if text:
        return PairingKey.parse(text), "torques signed with the pairing key it was given"
    path = user_key_file(environ)
    return user_key(path), f"torques signed with the user's pairing key ({path})"


BATCH_SWITCH_AFTER = 1.0
"""wall s: a batch of another simulator instance is taken once the one followed sent none
for this long (a simulator restarted by hand); before, it is a replay or a second simulator."""


class SignedBatches:
    """The check of a keyed observer of ``/sim/state_batch`` (``conversions.batch_states_or_log``'s
    ``verify``): a batch signed with ``key``, from one simulator instance, in order: its
    batches with a count after the last one taken; another instance's only once the one
    followed has been silent for :data:`BATCH_SWITCH_AFTER` wall s (``clock``: wall s)."""

    def __init__(self, key: "PairingKey", clock: Callable[[], float] = time.monotonic) -> None:
        self.key, self.clock = key, clock
        self.source: str | None = None
        self._count = 0
        self._wall = 0.0
        self.refused = 0  # batches refused (each logged, throttled)

    def __call__(self, label: str, data: bytes) -> None:
        """Take the batch whose first dimension is labelled ``label`` and whose values are
        ``data`` (float64 bytes), or ``ValueError`` saying why not."""
        try:
            source, count = self.key.verify_batch(label, data)
            now = self.clock()
            if source == self.source:
                if count <= self._count:
                    raise ValueError(f"the state batch {count} from {source} came again after batch {self._count} "
                                     "(a replay)")
            elif self.source is not None and now - self._wall < BATCH_SWITCH_AFTER:
                raise ValueError(f"the state batch is from simulator {source} while {self.source} runs (a replay "
                                 "from another run, or a second simulator)")
        except ValueError:
            self.refused += 1
            raise
        self.source, self._count, self._wall = source, count, now


class SignedStates:
    """A keyed controller's check of ``/joint_states``: a state signed with ``key``
    (:meth:`PairingKey.sign_state`), from one simulator instance, in (placement, stamp) order:
    the same state again is a lockstep re-send, an earlier one a replay (refused: before, three
    copies of a recorded state made the controller restart its walk and lose a decision), a
    later placement a reset. Another instance's states are taken only once the one followed
    has been silent for :data:`BATCH_SWITCH_AFTER` wall s (``clock``: wall s; a simulator
    restarted by hand)."""

    def __init__(self, key: "PairingKey", clock: Callable[[], float] = time.monotonic) -> None:
        self.key, self.clock = key, clock
        self.source: str | None = None
        self.placement = 0
        self._stamp = -1
        self._wall = 0.0

    def check(self, frame_id: str, stamp: int, q: Sequence[float], dq: Sequence[float]) -> int:
        """The placement count of a state to take, or ``ValueError`` saying why not."""
        signed = self.key.verify_state(frame_id, stamp, q, dq)
        if signed is None:
            raise ValueError("not signed with this stack's pairing key (its simulator runs without it, or another "
                             "node sent it)")
        source, placement = signed
        now = self.clock()
        if source == self.source:
            if (placement, stamp) < (self.placement, self._stamp):
                raise ValueError(f"placement {placement} at t = {stamp / 1e9:.3f} s of {source} came after placement "
                                 f"{self.placement} at t = {self._stamp / 1e9:.3f} s (a replay)")
        elif self.source is not None and now - self._wall < BATCH_SWITCH_AFTER:
            raise ValueError(f"it is from simulator {source} while {self.source} runs (a replay from another run, or "
                             "a second simulator)")
        self.source, self.placement, self._stamp, self._wall = source, placement, stamp, now
        return placement


class GaitOrder:
    """Signed gaits in order: per policy instance (the signature's source) only a gait counted
    after the last one taken, so a copy of a signed gait sent again later moves nothing."""

    def __init__(self) -> None:
        self._last: dict[str, int] = {}

    def take(self, source: str, count: int) -> bool:
        """Whether ``source``'s ``count``-th gait is new (and remember it if so)."""
        if count <= self._last.get(source, 0):
            return False
        self._last[source] = count
        return True
