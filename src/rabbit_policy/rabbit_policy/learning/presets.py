"""Training presets (rl-zoo style): a YAML file of ``scripts/train.py`` options, so a run is
one file to read, diff and repeat (``config/train/*.yaml``; ``train.py --config FILE``).

Keys are the options' names without the dashes (``warm_start`` or ``warm-start``), values
as on the command line; options given on the command line override the file. A key that is
no option, or a value outside an option's choices, is one line and exit status 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from rabbit_msgs_py.cli import yaml_problem


def parse_with_preset(parser: argparse.ArgumentParser, argv: list[str] | None) -> argparse.Namespace:
    """Parse ``argv`` with ``parser`` after applying the preset named by ``--config`` (if any)
    as the defaults; adds the ``--config`` option to ``parser``. An option the parser marks
    required may come from the preset: it is checked after both (one line, exit 2)."""
    parser.add_argument("--config", type=Path, default=None, metavar="YAML",
                        help="a preset file of these options (config/train/*.yaml); the command line overrides it")
    required = [a for a in parser._actions if a.required and a.option_strings]
    for action in required:
        action.required = False
    first = argparse.ArgumentParser(add_help=False)
    first.add_argument("--config", type=Path, default=None)
    known, _rest = first.parse_known_args(argv)
    if known.config is not None:
        apply_preset(parser, known.config)
    args = parser.parse_args(argv)
    missing = [a.option_strings[0] for a in required if getattr(args, a.dest) is None]
    if missing:
        parser.error(f"the following arguments are required: {', '.join(missing)}")
    return args


def apply_preset(parser: argparse.ArgumentParser, path: Path) -> None:
    """Make the options in the YAML file at ``path`` the parser's defaults (see the module docstring)."""
    import yaml

    try:
        values = yaml.safe_load(path.read_text())
    except OSError as exc:
        parser.error(f"--config {path}: {exc.strerror or exc}")
    except yaml.YAMLError as exc:
        parser.error(f"--config {path} is not YAML: {yaml_problem(exc)}")
    if not isinstance(values, dict):
        parser.error(f"--config {path}: a mapping of option names to values is expected")
    actions = {a.dest: a for a in parser._actions if a.option_strings}
    for key, value in values.items():
        dest = str(key).replace("-", "_")
        action = actions.get(dest)
        if action is None or dest in ("config", "help"):
            parser.error(f"--config {path}: {key!r} is not a train.py option")
        if action.choices is not None and value not in action.choices:
            parser.error(f"--config {path}: {key} = {value!r} is not one of {list(action.choices)}")
        if isinstance(action, (argparse._StoreTrueAction, argparse._StoreFalseAction)) and not isinstance(value, bool):
            parser.error(f"--config {path}: {key} must be true or false, got {value!r}")
        action.default = action.type(value) if action.type is not None and isinstance(value, str) else value
