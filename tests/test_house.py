"""The house's bars (issue 57): the tree is the product, not the lab notebook.

What the research log keeps under docs/learning/ is small and each file is there for a reader
(docs/learning/README.md); checkpoints outside the package and the test fixtures are only
the shipped controller's provenance and the tests'; ruff reads the whole tree."""

from __future__ import annotations

import re
import subprocess
import tomllib
from pathlib import Path

import pytest
from command_parsers import parser_of

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[1]
LEARNING = "docs/learning"
MAX_LEARNING_FILES = 60
MAX_LEARNING_BYTES = 3 * 1024 * 1024
MAX_LOOSE_CHECKPOINTS = 5


def tracked(*paths: str) -> list[str]:
    """Files git tracks under ``paths`` (the whole tree if none)."""
    out = subprocess.run(["git", "ls-files", "-z", "--", *paths], cwd=ROOT, capture_output=True, check=True)
    return [name for name in out.stdout.decode().split("\0") if name]


def test_the_research_log_keeps_few_small_files_and_says_why_each_stays():
    files = tracked(LEARNING)
    size = sum((ROOT / name).stat().st_size for name in files)
    assert len(files) <= MAX_LEARNING_FILES, f"{len(files)} files under {LEARNING}/"
    assert size <= MAX_LEARNING_BYTES, f"{size} bytes under {LEARNING}/"
    manifest = (ROOT / LEARNING / "README.md").read_text()
    for name in files:
        rel = name[len(LEARNING) + 1:]
        if rel == "README.md":
            continue
        # each kept file is named in the manifest, by its path, its name or its folder
        assert any(part in manifest for part in (rel, Path(rel).name, str(Path(rel).parent) + "/")), \
            f"{name} is kept but docs/learning/README.md does not say why"


def test_checkpoints_outside_the_package_and_fixtures_are_only_provenance():
    loose = [name for name in tracked() if name.endswith(".pt") and not name.startswith(("src/", "tests/"))]
    assert len(loose) <= MAX_LOOSE_CHECKPOINTS, loose


def test_ruff_reads_the_whole_tree():
    """No tracked folder is excluded: the only exclusions are the untracked virtual environment
    and run outputs."""
    config = tomllib.loads((ROOT / "ruff.toml").read_text())
    excluded = config.get("exclude", []) + config.get("extend-exclude", [])
    assert not [name for name in tracked() if any(name.startswith(folder.rstrip("/") + "/") for folder in excluded)]


def module_map() -> dict[str, set[str]]:
    """docs/architecture.md's module map: each package folder's row, as {folder: the modules it names}."""
    text = (ROOT / "docs/architecture.md").read_text()
    table = text[text.index("## The module map"):].split("\n## ")[0]
    rows = {}
    for line in table.splitlines():
        cells = line.split("|")
        if len(cells) > 2 and cells[1].strip().startswith("`rabbit_"):
            folder = cells[1].strip().strip("`").rstrip("/")
            rows[folder] = set(re.findall(r"`(\w+)\.py`", cells[2]))
    return rows


def package_folders() -> dict[str, set[str]]:
    """Every folder of python modules in the four packages, as {folder: its modules}."""
    folders: dict[str, set[str]] = {}
    for name in tracked("src"):
        path = Path(name)
        if path.suffix != ".py" or path.name in ("__init__.py", "setup.py") or len(path.parts) < 4:
            continue
        if path.parts[2] != path.parts[1]:  # src/<pkg>/<pkg>/...: the package, not its tests
            continue
        folders.setdefault("/".join(path.parts[2:-1]), set()).add(path.stem)
    return folders


def test_the_module_map_is_the_tree():
    rows, tree = module_map(), package_folders()
    assert set(rows) == set(tree), f"folders without a row: {set(tree) - set(rows)}; rows without a folder: " \
                                   f"{set(rows) - set(tree)}"
    for folder, modules in tree.items():
        assert rows[folder] == modules, f"{folder}/: the map misses {sorted(modules - rows[folder])} and names " \
                                        f"{sorted(rows[folder] - modules)} that are not there"


def test_the_readme_is_a_short_front_door():
    """At most 150 lines, and none over 120 characters (the headline table's rows included: short
    labels, its legend under it)."""
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= 150
    assert [n for n, line in enumerate(lines, 1) if len(line) > 120] == []


def test_no_test_file_passes_600_lines():
    """tests/ is laid out by concern: a file a reader can hold (issue 74)."""
    long = {name: n for name in tracked("tests") if name.endswith(".py")
            and (n := len((ROOT / name).read_text().splitlines())) > 600}
    assert not long, f"test files over 600 lines (split them by concern): {long}"


def test_nodes_are_thin_and_scripts_are_shims():
    sim_node = (ROOT / "src/rabbit_sim/rabbit_sim/sim_node.py").read_text()
    assert len(sim_node.splitlines()) <= 300 and "noqa: E402" not in sim_node
    long = {p.name: n for p in (ROOT / "scripts").glob("*.py") if (n := len(p.read_text().splitlines())) > 30}
    assert not long, f"scripts over 30 lines (a script is a shim over a commands module): {long}"


def test_shared_options_are_declared_once():
    """walk.py and run_stack.py take the walk's options from one declaration (the same types,
    defaults and choices); ``--workers`` and ``--classic-integral`` are each declared in one place."""
    from rabbit_policy.commands import run_stack, walk

    def actions(parser):
        return {a.dest: (a.type, a.default, a.choices, a.option_strings) for a in parser._actions}

    fast, stack = actions(walk.build_parser()), actions(run_stack.build_parser())
    for dest in ("controller", "speed", "speed_schedule", "duration", "push", "model", "friction",
                 "torso_mass_scale", "torque_delay", "policy_file", "decision_period", "speed_integral"):
        assert fast[dest] == stack[dest], dest
    for option, home in (("--workers", "parallel.py"), ("--classic-integral", "experiment/options.py")):
        declared = [name for name in tracked("src") if name.endswith(".py")
                    and f'add_argument("{option}"' in (ROOT / name).read_text()]
        assert declared == [f"src/rabbit_policy/rabbit_policy/{home}"], (option, declared)



def command_parsers() -> dict[str, object]:
    """Every command's argument parser, as its ``main`` builds it (:func:`parser_of`)."""
    import importlib
    import inspect
    import pkgutil

    import rabbit_policy.commands
    import rabbit_sim.commands

    parsers = {}
    for package in (rabbit_policy.commands, rabbit_sim.commands):
        for info in pkgutil.iter_modules(package.__path__):
            main = importlib.import_module(f"{package.__name__}.{info.name}").main
            parsers[info.name] = parser_of(lambda: main([]) if inspect.signature(main).parameters else main(),
                                           info.name)
    return parsers


# options that parse differently in some commands, and why
OPTIONS_OF_ONE_KIND = {
    "--decision-period": "training's takes step or N ticks, not own: an environment has no timing of its own",
}


def test_an_option_means_one_kind_of_value_in_every_command():
    """An option spelled the same in two commands parses the same way (the same type and
    action: ``--out`` is a path, ``--speed`` a number > 0, ``--gait-dir`` a directory or "",
    ``--decision-period`` a timing), whatever each command writes there or defaults to."""
    parsers = command_parsers()
    assert len(parsers) >= 25, sorted(parsers)
    kinds: dict[str, set] = {}
    for command, parser in parsers.items():
        for action in parser._actions:
            for flag in action.option_strings:
                kind = getattr(action.type, "__name__", None) or "str"  # argparse's default type: the text
                kinds.setdefault(flag, set()).add((kind, type(action).__name__))
    mixed = {flag: kind for flag, kind in kinds.items() if len(kind) > 1 and flag not in OPTIONS_OF_ONE_KIND}
    assert not mixed, mixed

# where a decision timing is named otherwise, and why
OTHER_TIMING_NAMES = {
    ("rabbit_policy.runtime.decision_clock", "DecisionClock.__init__", "period"): "the clock's own period",
    ("rabbit_policy.spec.schema", "DecisionSpec.__init__", "period_ticks"): "the spec file's field",
    ("rabbit_policy.spec.schema", "ControllerSpec.__init__", "decision"): "the spec file's section",
    ("rabbit_policy.runtime.alpha_blend", "AlphaBlend.__init__", "period_s"): "a hold in s, not a timing",
}


def signatures(package):
    """(module, qualified name, signature) of every function and method ``package`` defines."""
    import importlib
    import inspect
    import pkgutil

    for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
        module = importlib.import_module(info.name)
        for name, obj in vars(module).items():
            if getattr(obj, "__module__", None) != module.__name__:
                continue
            members = [(name, obj)] if inspect.isfunction(obj) else [
                (f"{name}.{n}", getattr(f, "__func__", f)) for n, f in vars(obj).items()
                if inspect.isfunction(getattr(f, "__func__", f))] if inspect.isclass(obj) else []
            for qualname, function in members:
                yield info.name, qualname, inspect.signature(function)


def test_a_decision_timing_has_one_type_where_it_enters_and_one_name_once_resolved():
    """A decision timing a user asks for (own, step, N ticks) is a ``decision: DecisionTiming``
    wherever it enters (make_policy, a checkpoint's conversion, the stack's configuration); once
    resolved it is ``decision_period: int`` (ticks, 0 once per step) through the policies, the
    loops and the environments. No third spelling (period, ticks, None for own)."""
    import rabbit_policy

    timing = re.compile(r"^(decision|decision_(period|ticks|timing)|timing|period|period_(ticks|s)|ticks)$")
    wrong = []
    for module, qualname, signature in signatures(rabbit_policy):
        for name, parameter in signature.parameters.items():
            if not timing.match(name) or (module, qualname, name) in OTHER_TIMING_NAMES:
                continue
            expected = {"decision": "DecisionTiming", "decision_period": "int"}.get(name)
            if str(parameter.annotation) != expected:
                wrong.append(f"{module}.{qualname}({name}: {parameter.annotation})")
    assert not wrong, wrong


def test_the_node_loads_the_runtime_apart_from_learning_and_evaluation():
    """policy_node with the three packaged controllers built loads runtime/, spec/ and the
    schedule's parser, nothing of learning, evaluation, gait design, bring-up or the commands,
    nor torch or Gymnasium (docs/architecture.md: why rabbit_policy stays one package)."""
    import json
    import sys

    code = ("import json, sys; import rabbit_policy.policy_node; "
            "from rabbit_policy.spec.make import make_policy; "
            "[make_policy(kind) for kind in ('classic', 'learned', 'recovery')]; "
            "print(json.dumps(sorted(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 0, out.stderr[-2000:]
    loaded = json.loads(out.stdout)
    ours = {name for name in loaded if name.startswith("rabbit_policy.")}
    floors = {name.split(".")[1] for name in ours}
    assert floors <= {"policy_node", "policy_driver", "registration", "runtime", "spec", "experiment"}, floors
    assert {name for name in ours if name.startswith("rabbit_policy.experiment.")} <= {
        "rabbit_policy.experiment.scenario"}
    assert not {"torch", "gymnasium"} & set(loaded)


LOCAL_IMPORTS_ALLOWED = 10
"""Function-local imports of project modules in library code (the commands aside), at most."""


def test_function_local_project_imports_are_few_and_each_says_why():
    """A project module imported inside a function hides a tie from a reader and from the tools
    (issue 74): library code keeps at most :data:`LOCAL_IMPORTS_ALLOWED`, each with a comment on
    its line or its group's (an optional heavy dependency: torch, OpenGL, a display, rosbags)."""
    import ast

    ours = ("rabbit_policy", "rabbit_sim", "rabbit_hzd_controller", "rabbit_msgs_py")
    found, silent = [], []
    for name in tracked("src"):
        if not name.endswith(".py") or "/commands/" in name:
            continue
        lines = (ROOT / name).read_text().splitlines()
        for node in ast.walk(ast.parse("\n".join(lines))):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for inner in ast.walk(node):
                project = (isinstance(inner, ast.ImportFrom) and (inner.level > 0 or (inner.module or "").split(".")[0]
                                                                  in ours)) or \
                          (isinstance(inner, ast.Import) and any(a.name.split(".")[0] in ours for a in inner.names))
                if project:
                    found.append(f"{name}:{inner.lineno}")
                    if not any("#" in lines[k] for k in range(max(0, inner.lineno - 3), inner.end_lineno)):
                        silent.append(f"{name}:{inner.lineno}")
    assert len(found) <= LOCAL_IMPORTS_ALLOWED, found
    assert not silent, f"function-local project imports without a comment saying why: {silent}"


def folder_imports() -> dict[str, set[str]]:
    """Which folder of the four packages imports which (``rabbit_policy/spec`` ->
    ``rabbit_policy/runtime``), counting every import: module level, function-local and
    relative. A package's top-level modules (its nodes) are a folder like any other: a
    sub-folder that imports them is an arrow up (rabbit_sim's stepping core once imported the
    package's physics modules while the package's node imported it: the physics moved to a
    folder of its own)."""
    import ast

    modules: dict[str, str] = {}
    for name in tracked("src"):
        path = Path(name)
        if path.suffix == ".py" and len(path.parts) >= 4 and path.parts[1] == path.parts[2]:
            dotted = list(path.parts[2:-1]) + ([] if path.stem == "__init__" else [path.stem])
            modules[".".join(dotted)] = "/".join(path.parts[2:-1])
    edges: dict[str, set[str]] = {}
    for name in tracked("src"):
        path = Path(name)
        if path.suffix != ".py" or len(path.parts) < 4 or path.parts[1] != path.parts[2]:
            continue
        here = "/".join(path.parts[2:-1])
        package = list(path.parts[2:-1])
        for node in ast.walk(ast.parse((ROOT / name).read_text())):
            targets = []
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    base = ".".join(package[:len(package) - node.level + 1] + ([base] if base else []))
                targets = [base] + [f"{base}.{alias.name}" for alias in node.names]
            for target in targets:
                folder = modules.get(target)
                if folder is not None and folder != here:
                    edges.setdefault(here, set()).add(folder)
    return edges


def test_no_two_folders_import_each_other_round_a_circle():
    """Every folder on one floor (issue 74): following the imports between folders never comes
    back to where it started, so each folder can be read knowing only those below it."""
    edges = folder_imports()
    assert edges.get("rabbit_policy/spec") and "rabbit_policy/runtime" in edges["rabbit_policy/spec"]
    circles = []
    for start in sorted(edges):
        seen, path = set(), [start]

        def walk(folder: str) -> None:
            for nxt in sorted(edges.get(folder, ())):
                if nxt == start:
                    circles.append(" -> ".join(path + [start]))
                elif nxt not in seen:
                    seen.add(nxt)
                    path.append(nxt)
                    walk(nxt)
                    path.pop()
        walk(start)
    assert not circles, f"folders importing round a circle: {circles[:5]}"


def test_no_spec_section_mirrors_a_runtime_class():
    """One class per rule (issue 74): a spec section is the runtime's own dataclass, or a
    subclass adding what only the file needs (the controller section's model hash); no class
    of the schema declares three or more of a runtime dataclass's fields again (a name and its
    type: the network section's ``low`` is a list of numbers in the file, an array in the
    forward pass; that is a file's description of the runtime's arrays, not a copy)."""
    import dataclasses
    import importlib
    import pkgutil

    import rabbit_hzd_controller
    import rabbit_policy.runtime
    from rabbit_policy.spec import schema

    runtime = []
    for package in (rabbit_policy.runtime, rabbit_hzd_controller):
        for info in pkgutil.iter_modules(package.__path__):
            if info.name.endswith("_node"):
                continue
            module = importlib.import_module(f"{package.__name__}.{info.name}")
            runtime += [c for c in vars(module).values()
                        if isinstance(c, type) and dataclasses.is_dataclass(c) and c.__module__ == module.__name__]
    assert len(runtime) >= 10
    spec_classes = [c for c in vars(schema).values()
                    if isinstance(c, type) and dataclasses.is_dataclass(c) and c.__module__ == schema.__name__]
    mirrors = []
    for spec_class in spec_classes:
        own = set(spec_class.__dict__.get("__annotations__", {}).items())
        for cls in runtime:
            shared = {name for name, kind in own & {(f.name, str(f.type)) for f in dataclasses.fields(cls)}}
            if len(shared) >= 3:
                mirrors.append(f"{spec_class.__name__} ~ {cls.__name__}: {sorted(shared)}")
    assert not mirrors, mirrors


def test_no_function_in_the_packages_passes_120_lines():
    """Straight roads (issue 74): no function or method of the four packages is longer than 120
    lines, so each reads on a screen or two."""
    import ast

    long = []
    for name in tracked("src"):
        if name.endswith(".py"):
            for node in ast.walk(ast.parse((ROOT / name).read_text())):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and \
                        node.end_lineno - node.lineno + 1 > 120:
                    long.append(f"{name}:{node.lineno} {node.name} ({node.end_lineno - node.lineno + 1} lines)")
    assert not long, long
