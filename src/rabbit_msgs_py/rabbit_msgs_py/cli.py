"""Command-line parsing shared by the scripts (ROS-free): bad arguments give one line
(``prog: error: ...``) on stderr and exit status 2, without argparse's usage block."""

from __future__ import annotations

import argparse
import sys


class ArgumentParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` whose errors are one line (``--help`` shows the usage)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        print(f"{self.prog}: error: {message}", file=sys.stderr)
        sys.exit(2)
