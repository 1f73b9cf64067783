"""Docs that cannot drift from the code: every ``scripts/*.py`` command line in README.md and
docs/*.md uses flags its script's parser has, by their one spelling (aliases are for old
command lines, not for the docs)."""

from __future__ import annotations

import argparse
import contextlib
import io
import re
import shlex
import runpy
import sys
from pathlib import Path

import pytest

from rabbit_msgs_py.cli import ArgumentParser

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = sorted(p.stem for p in (ROOT / "scripts").glob("*.py"))
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

# a script's name, then its arguments up to the end of the command: a shell separator, a
# comment or a line end that no backslash continues
CALL = re.compile(r"\b(" + "|".join(SCRIPTS) + r")\.py\b((?:\\\n|[^\n|;&#])*)")
FLAG = re.compile(r"(?<![\w-])(--[a-z][a-z0-9-]*)")
FENCED = re.compile(r"^```[a-z]*\n(.*?)^```", re.S | re.M)
INLINE = re.compile(r"`([^`]+)`")
PLACEHOLDER = re.compile(r"\[|\.\.\.|…|\{")  # an optional part, "and so on", a choice: not one command line


class _Parsed(Exception):
    def __init__(self, parser: argparse.ArgumentParser) -> None:
        self.parser = parser


def script_parser(name: str) -> argparse.ArgumentParser:
    """``scripts/<name>.py``'s parser, taken as the script builds it: its ``main`` runs
    until it parses, and stops there."""
    def capture(self, *_args, **_kwargs):
        raise _Parsed(self)

    saved = ArgumentParser.parse_args, ArgumentParser.parse_known_args, sys.argv
    ArgumentParser.parse_args = ArgumentParser.parse_known_args = capture
    sys.argv = [f"{name}.py"]
    try:
        runpy.run_path(str(ROOT / "scripts" / f"{name}.py"), run_name="__main__")
    except _Parsed as parsed:
        return parsed.parser
    finally:
        ArgumentParser.parse_args, ArgumentParser.parse_known_args, sys.argv = saved
    raise AssertionError(f"scripts/{name}.py never parsed its command line")


def script_options(name: str) -> tuple[set[str], set[str]]:
    """(every option string, the primary ones) of ``scripts/<name>.py``'s parser."""
    actions = script_parser(name)._actions  # argparse keeps its actions in this list
    every = {o for a in actions for o in a.option_strings}
    primary = {next((o for o in a.option_strings if o.startswith("--")), a.option_strings[0])
               for a in actions if a.option_strings}
    return every, primary


def code_spans(text: str):
    """(line, code) of every fenced block and inline code span of a markdown text; an
    inline span's line breaks are spaces."""
    for block in FENCED.finditer(text):
        yield text.count("\n", 0, block.start()) + 2, block.group(1)
    outside = FENCED.sub(lambda m: "\n" * m.group(0).count("\n"), text)
    for span in INLINE.finditer(outside):
        yield outside.count("\n", 0, span.start()) + 1, span.group(1).replace("\n", " ")


def documented_calls() -> list[tuple[str, int, str, str]]:
    """(doc, line, script, its arguments) for every script command line in the docs' code."""
    calls = []
    for doc in DOCS:
        for line, code in code_spans(doc.read_text()):
            for match in CALL.finditer(code):
                calls.append((doc.name, line + code.count("\n", 0, match.start()), match.group(1),
                              match.group(2).replace("\\\n", " ")))
    return calls


def test_the_docs_name_scripts_that_exist_and_show_command_lines():
    calls = documented_calls()
    assert len(calls) > 60 and {c[2] for c in calls} >= {"run_stack", "walk", "train", "evaluate", "record"}
    for doc in DOCS:
        for name in re.findall(r"scripts/(\w+)\.py", doc.read_text()):
            assert name in SCRIPTS, f"{doc.name} names scripts/{name}.py, which does not exist"


def test_every_documented_command_line_parses_with_its_scripts_one_spelling():
    """Each flag exists and is the script's one spelling; a whole command line (no
    synopsis such as ``[--flag]`` or ``...``) parses as the script would parse it, a value
    written as a placeholder (``V``, ``HZ``) aside."""
    wrong = []
    for doc, line, script, arguments in documented_calls():
        parser = script_parser(script)
        every, primary = script_options(script)
        for flag in FLAG.findall(arguments):
            if flag not in every:
                wrong.append(f"{doc}:{line}: {script}.py has no {flag}")
            elif flag not in primary:
                wrong.append(f"{doc}:{line}: {script}.py {flag} is an alias; the docs use its one spelling")
        if not arguments.strip() or PLACEHOLDER.search(arguments):
            continue  # a script named in prose, or a synopsis
        error = io.StringIO()
        with contextlib.redirect_stderr(error):
            try:
                parser.parse_args(shlex.split(arguments))
            except SystemExit as exc:
                if exc.code and not re.search(r"invalid .*value: '[A-Z][A-Z_]*'", error.getvalue()):
                    wrong.append(f"{doc}:{line}: {script}.py{arguments.rstrip()}: {error.getvalue().strip()}")
    assert not wrong, "\n".join(wrong)


def test_one_spelling_per_flag_across_scripts():
    """A value that two scripts take has one primary flag in both, and no script's alias is
    another's primary flag for something else."""
    primary_of: dict[str, dict[str, str]] = {}  # dest -> {script: primary flag}
    dest_of: dict[str, dict[str, str]] = {}  # primary flag -> {script: dest}
    aliases: list[tuple[str, str, str]] = []
    for name in SCRIPTS:
        for action in script_parser(name)._actions:
            flags = [o for o in action.option_strings if o.startswith("--") and o != "--help"]
            if not flags:
                continue
            primary_of.setdefault(action.dest, {})[name] = flags[0]
            dest_of.setdefault(flags[0], {})[name] = action.dest
            aliases += [(name, alias, action.dest) for alias in flags[1:]]
    for dest, spelled in primary_of.items():
        assert len(set(spelled.values())) == 1, f"{dest} is spelled {spelled}"
    for name, alias, dest in aliases:
        for other, other_dest in dest_of.get(alias, {}).items():
            assert other_dest == dest, f"{name}.py's alias {alias} is {other}.py's flag for {other_dest}"
