"""Explicit pairing of a simulator with its controller: signed torque replies.

A stack (run_stack) makes a random key and gives it to ``sim_node`` and
``hzd_controller_node`` (parameter ``pairing_key``; each node reads it once at start and then
removes the parameter, so ``ros2 param get`` cannot read it). The controller signs every
torque reply: its ``header.frame_id`` is ``<instance id>#<tag>``, the tag a keyed BLAKE2b
MAC (64 bits) of the stamp it answers (ns) and its four torques (N m, as float64). The
simulator applies only replies whose tag checks with its key. A node without the key cannot
make a tag for a new stamp or new torques, even after seeing every earlier reply: replaying
a seen reply repeats the real controller's torques for a stamp no longer due (ignored).

This guards the robot against other nodes on the ROS graph (a second controller, a test
script, a node that answers every state). It is not SROS2: a process of the same user can
read the key from the command line of the nodes it was given to.
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
import struct
from dataclasses import dataclass
from typing import Sequence

TAG_SEPARATOR = "#"
MIN_KEY_CHARS = 16
MAX_KEY_BYTES = 64  # BLAKE2b's longest key


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
