"""Command-line parsing shared by the scripts (ROS-free): bad arguments give one line
(``prog: error: ...``) on stderr and exit status 2, without argparse's usage block."""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys
import tempfile
from pathlib import Path


class HelpFormatter(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """The description as written (a script's docstring) and every option's default."""


class ArgumentParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` whose errors are one line (``--help`` shows the usage)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        print(f"{self.prog}: error: {message}", file=sys.stderr)
        sys.exit(2)


def unwritable_dir(path: Path) -> str | None:
    """Why the directory ``path`` cannot be made or written (one line), or None: its nearest
    existing ancestor (itself if it exists) must be a directory a file can be written in (a
    file is made there and removed at once; nothing else is left behind)."""
    probe = Path(os.path.abspath(path))
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    if not probe.is_dir():
        return f"cannot write there ({probe} is not a directory)"
    try:
        with tempfile.NamedTemporaryFile(dir=probe, prefix=".write-check-"):
            pass
    except OSError as exc:
        return f"cannot write there ({exc.strerror or exc})"
    return None


def ensure_output_dir(parser: argparse.ArgumentParser, path, flag: str = "--out", empty: bool = False) -> None:
    """Check, before any work, that an output directory can be made and written (and, with
    ``empty``, that it holds nothing if it exists); otherwise ``parser.error``: one line, exit
    status 2."""
    path = Path(path)
    problem = unwritable_dir(path)
    if problem:
        parser.error(f"{flag} {path}: {problem}")
    if empty and path.is_dir() and any(path.iterdir()):
        parser.error(f"{flag} {path} is not empty: give a new directory")


def run_dir_problem(out: Path, resume: bool, checkpoint: str) -> str | None:
    """Why ``out`` cannot hold a training run (one line), or None: it cannot be written, or it
    holds files and ``resume`` is not given, or ``resume`` is given and ``out/checkpoint`` (the
    file a resumed run continues from) is not there."""
    out = Path(out)
    problem = unwritable_dir(out)
    if problem:
        return f"--out {out}: {problem}"
    if resume and not (out / checkpoint).is_file():
        return f"--resume: no {out / checkpoint}"
    if not resume and out.is_dir() and any(out.iterdir()):
        return f"{out} is not empty; use --resume or another --out"
    return None


def refuse_unusable_run_dir(argv: list[str] | None, prog: str, checkpoint: str) -> None:
    """A training command's first step, before its heavy imports (torch, the environments):
    read ``--out`` and ``--resume`` alone from ``argv`` (the command's own parser reads them
    again with everything else) and, when :func:`run_dir_problem` says why the run cannot go
    there, print ``prog: error: ...`` and exit with status 2. Without ``--out`` it does nothing:
    the command's parser says it is missing."""
    early = argparse.ArgumentParser(prog=prog, add_help=False, allow_abbrev=False, exit_on_error=False)
    early.add_argument("--out", type=Path)
    early.add_argument("--resume", action="store_true")
    try:
        known, _ = early.parse_known_args(sys.argv[1:] if argv is None else argv)
    except argparse.ArgumentError:  # such as --out without a value: the command's parser says so
        return
    problem = None if known.out is None else run_dir_problem(known.out, known.resume, checkpoint)
    if problem:
        print(f"{prog}: error: {problem}", file=sys.stderr)
        sys.exit(2)


def positive(text: str) -> float:
    """An argparse type: a finite number > 0."""
    value = float(text)
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return value


def positive_int(text: str) -> int:
    """An argparse type: a whole number >= 1."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 1, got {text}")
    return value


def non_negative(text: str) -> float:
    """An argparse type: a finite number >= 0."""
    value = float(text)
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text}")
    return value


# ------------------------------------------------------------------ a command line from a dataclass
def option(default, help: str, *, flag: str | None = None, aliases: tuple[str, ...] = (),
           choices: tuple | None = None, type=None, cli: bool = True, range: tuple[float, float] | None = None,
           step: float = 0.0, secret: bool = False):
    """A configuration dataclass field that documents itself and becomes one command-line
    option (CleanRL's ``Args`` style: one place for each default): ``help`` says what it is
    and its unit; ``flag`` overrides ``--field-name``; ``aliases`` are older spellings;
    ``cli=False`` keeps it off the command line; ``range`` (closed) and ``step`` go into a
    node parameter's descriptor where the field is one; ``secret`` keeps the value out of the
    dataclass's repr (a key)."""
    return dataclasses.field(default=default, repr=not secret, metadata={"help": help, "flag": flag, "aliases": aliases,
                                                        "choices": choices, "type": type, "cli": cli,
                                                        "range": range, "step": step})


def config_flag(field: dataclasses.Field) -> str:
    """The command-line flag of a configuration field."""
    return field.metadata.get("flag") or "--" + field.name.replace("_", "-")


def _dest(field: dataclasses.Field) -> str:
    return config_flag(field)[2:].replace("-", "_")


def add_config_arguments(parser, cls, exclude: tuple[str, ...] = ()) -> None:
    """One option per field of the dataclass ``cls`` (made with :func:`option`) on ``parser``
    (or an argument group), its default the field's. A field whose flag the parser has
    already (one shared with another configuration) is left to that option; the two
    defaults must agree."""
    existing = {o: a for a in getattr(parser, "_actions", []) for o in a.option_strings}
    for field in dataclasses.fields(cls):
        if field.name in exclude or not field.metadata.get("cli", True) or "help" not in field.metadata:
            continue
        flag = config_flag(field)
        if flag in existing:
            if existing[flag].default != field.default:
                raise ValueError(f"{cls.__name__}.{field.name}: {flag} is shared with a default of "
                                 f"{existing[flag].default!r}, not {field.default!r}")
            continue
        kwargs = {"dest": _dest(field), "default": field.default, "help": field.metadata["help"]}
        if isinstance(field.default, bool):
            kwargs["action"] = "store_true" if field.default is False else argparse.BooleanOptionalAction
        else:
            kwargs["type"] = field.metadata.get("type") or type(field.default)
            if field.metadata.get("choices"):
                kwargs["choices"] = field.metadata["choices"]
        parser.add_argument(flag, *field.metadata.get("aliases", ()), **kwargs)


def config_from_args(cls, args: argparse.Namespace, **given):
    """An instance of ``cls`` from the options :func:`add_config_arguments` added (``given``:
    the fields set otherwise)."""
    values = {f.name: getattr(args, _dest(f)) for f in dataclasses.fields(cls)
              if f.name not in given and hasattr(args, _dest(f)) and f.metadata.get("cli", True)}
    return cls(**values, **given)


def yaml_problem(exc) -> str:
    """A YAML error in one line: what is wrong and where (line and column, from 1), e.g.
    "line 3, column 7: expected ',' or ']', but got '<stream end>'"."""
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    what = getattr(exc, "problem", None) or str(exc).splitlines()[0]
    return f"line {mark.line + 1}, column {mark.column + 1}: {what}" if mark is not None else what
