"""A command's argument parser, taken as the command builds it: its ``main`` (or a script run
as ``__main__``) runs until it parses, and stops there. Shared by the docs' and the house's
tests."""

from __future__ import annotations

import sys
from typing import Callable
from unittest import mock

from rabbit_msgs_py.cli import ArgumentParser


class _Parsed(Exception):
    def __init__(self, parser: ArgumentParser) -> None:
        self.parser = parser


def parser_of(run: Callable[[], object], name: str) -> ArgumentParser:
    """The parser ``run`` builds, ``name`` naming it in the error if it never parses. Only
    our :class:`~rabbit_msgs_py.cli.ArgumentParser` stops (every command's): a plain argparse
    parser inside, such as a preset's pre-parser for ``--config``, still parses. The patch is
    undone on the way out (the class gets back no attribute of its own)."""
    def capture(self, *_args, **_kwargs):
        raise _Parsed(self)

    with mock.patch.object(ArgumentParser, "parse_args", capture), \
            mock.patch.object(ArgumentParser, "parse_known_args", capture), \
            mock.patch.object(sys, "argv", [name]):
        try:
            run()
        except _Parsed as parsed:
            return parsed.parser
    raise AssertionError(f"{name} never parsed its command line")
