"""Child processes of a process, read from /proc (Linux): ``ps`` cuts its lines at 80 columns
under pytest, so a command line matched there loses its end behind a long checkout path."""

from __future__ import annotations

from pathlib import Path


def children(parent: int, needle: str) -> list[str]:
    """The pids of ``parent``'s children whose command line contains ``needle``."""
    found = []
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            ppid = int((proc / "stat").read_text().rsplit(")", 1)[1].split()[1])
            command = (proc / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except (OSError, ValueError, IndexError):  # it ended while read
            continue
        if ppid == parent and needle in command:
            found.append(proc.name)
    return found
