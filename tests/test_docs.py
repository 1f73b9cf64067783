"""Docs that cannot drift from the code: every ``scripts/*.py`` command line in README.md and
docs/*.md uses flags its script's parser has, by their one spelling (aliases are for old
command lines, not for the docs)."""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import re
import shlex
import runpy
import subprocess
import sys
from pathlib import Path

import pytest

from command_parsers import parser_of

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


def script_parser(name: str) -> argparse.ArgumentParser:
    """``scripts/<name>.py``'s parser, taken as the script builds it (:func:`parser_of`)."""
    return parser_of(lambda: runpy.run_path(str(ROOT / "scripts" / f"{name}.py"), run_name="__main__"),
                     f"scripts/{name}.py")


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
    for block in FENCED.finditer(text):  # shell comments are prose, not commands
        yield text.count("\n", 0, block.start()) + 2, re.sub(r"(^|\s)#.*", "", block.group(1), flags=re.M)
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


@pytest.mark.unit
def test_the_docs_name_scripts_that_exist_and_show_command_lines():
    calls = documented_calls()
    assert len(calls) > 60 and {c[2] for c in calls} >= {"run_stack", "walk", "train", "evaluate", "record"}
    for doc in DOCS:
        for name in re.findall(r"scripts/(\w+)\.py", doc.read_text()):
            assert name in SCRIPTS, f"{doc.name} names scripts/{name}.py, which does not exist"


@pytest.mark.unit
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


@pytest.mark.unit
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
            primary_of.setdefault(action.dest, {}).setdefault(name, flags[0])  # the first option for it
            dest_of.setdefault(flags[0], {})[name] = action.dest
            aliases += [(name, alias, action.dest) for alias in flags[1:]]
    for dest, spelled in primary_of.items():
        assert len(set(spelled.values())) == 1, f"{dest} is spelled {spelled}"
    for name, alias, dest in aliases:
        for other, other_dest in dest_of.get(alias, {}).items():
            assert other_dest == dest, f"{name}.py's alias {alias} is {other}.py's flag for {other_dest}"


@pytest.mark.sim
def test_the_documented_gymnasium_ids_make_an_environment():
    import gymnasium

    import rabbit_policy  # noqa: F401  (registers the ids, as the docs' snippets do; not left to an earlier test)

    ids = {m for doc in DOCS for m in re.findall(r'gymnasium\.make\("([^"]+)"\)', doc.read_text())}
    assert ids
    for env_id in ids:
        env = gymnasium.make(env_id)
        env.reset(seed=0)
        env.close()


# ------------------------------------------------------------------ docs/architecture.md
def _architecture_section(start: str, end: str) -> str:
    text = (ROOT / "docs" / "architecture.md").read_text()
    return text[text.index(start):text.index(end, text.index(start))]


@pytest.mark.unit
def test_architecture_lists_every_topic_with_its_type_and_qos():
    from rclpy.qos import DurabilityPolicy

    from rabbit_msgs_py import qos, topics
    from rabbit_msgs_py.catalog import STACK_TOPICS, TopicSpec
    from rosgraph_msgs.msg import Clock

    specs = {topics.resolve(name): spec for name, spec in  # the docs name them in the root namespace
             {**STACK_TOPICS, topics.RECORDED_UNTIL: TopicSpec(topics.RECORDED_UNTIL, Clock, qos.STATUS_QOS)}.items()}
    table = _architecture_section("| topic | type | who | QoS |", "\nServices")
    rows = [[cell.strip() for cell in re.split(r"(?<!\\)\|", line)[1:-1]]
            for line in table.splitlines()[2:] if line.startswith("| `/")]
    assert sorted(r[0].strip("`") for r in rows) == sorted(specs)
    for name, kind, _who, qos_text in rows:
        spec = specs[name.strip("`")]
        assert kind.startswith(spec.type_name.replace("/msg/", "/")), (name, kind)
        depth = re.search(r"keep last (\d+)", qos_text)
        transient = spec.qos.durability == DurabilityPolicy.TRANSIENT_LOCAL
        assert ("transient local" in qos_text) == transient, (name, qos_text)
        assert (depth is None and transient) or int(depth.group(1)) == spec.qos.depth, (name, qos_text)


@pytest.mark.unit
def test_architecture_names_the_services_and_every_node_parameter():
    from rabbit_hzd_controller.hzd_controller_node import CONTROLLER_PARAMS, NODE_PARAMS
    from rabbit_msgs_py import topics
    from rabbit_policy.policy_node import POLICY_PARAMS
    from rabbit_sim.recorder_node import RECORDER_PARAMS
    from rabbit_sim.sim_node import SIM_PARAMS

    services = _architecture_section("Services (sim_node)", "\n\n")
    assert sorted(re.findall(r"`(/[\w/]+)`", services)) == sorted(
        [topics.resolve(name) for name in (topics.RESET_SERVICE, topics.PAUSE_SERVICE, topics.RELEASE_CONTROLLER_SERVICE)])
    declared = {"sim_node": SIM_PARAMS, "hzd_controller_node": {**CONTROLLER_PARAMS, **NODE_PARAMS},
                "policy_node": POLICY_PARAMS, "recorder_node": RECORDER_PARAMS}
    table = _architecture_section("| node (", "\n\n")
    documented = {}
    for line in table.splitlines()[2:]:
        node, parameters = [cell.strip() for cell in re.split(r"(?<!\\)\|", line)[1:-1]]
        documented[re.search(r"(\w+_node)`", node).group(1)] = set(re.findall(r"`(\w+)` \(", parameters))
    assert {k: sorted(v) for k, v in documented.items()} == {k: sorted(v) for k, v in declared.items()}


@pytest.mark.sim
def test_architecture_names_walk_json_keys_as_walk_prints_them(capsys):
    import json

    text = _architecture_section("`--json`: one object, always the same keys (", ").")
    documented = re.findall(r"`(\w+)`", text)
    saved = sys.argv
    sys.argv = ["walk.py", "--speed", "1.0", "--duration", "0.3", "--json"]
    try:
        runpy.run_path(str(ROOT / "scripts" / "walk.py"), run_name="__main__")
    except SystemExit as exc:
        assert exc.code == 0
    finally:
        sys.argv = saved
    assert documented == list(json.loads(capsys.readouterr().out))


@pytest.mark.unit
def test_every_relative_link_in_the_docs_reaches_a_file():
    broken = []
    for doc in DOCS:
        for target in re.findall(r"\]\(([^)\s]+)\)", doc.read_text()):
            if re.match(r"[a-z]+://|#|mailto:", target):
                continue
            if not (doc.parent / target.split("#")[0]).exists():
                broken.append(f"{doc.name}: {target}")
    assert not broken, broken


# what the README's "Running it" commands become in the test: short, into a temporary directory;
# the long ones are covered by their own tests (named here) and only parsed above
README_SHORTENED = {"--duration": "3"}  # long enough to reach the command (else exit 4)
README_NOT_RUN = {
    "--viewer": "tests/sim/test_visualization.py (needs a display)",
    "evaluate.py": "tests/policy/test_evaluation.py::test_evaluate_quick_writes_report_results_figures_and_videos",
    "train.py": "tests/policy/test_training.py (the trainers, resume, signals)",
}


@pytest.mark.ros
@pytest.mark.slow
def test_the_readme_running_it_commands_run(tmp_path):
    import os
    import subprocess

    from rabbit_policy.spec.provenance import code_commit

    text = (ROOT / "README.md").read_text()
    block = FENCED.search(text, text.index("## Running it")).group(1)
    ran = []
    for line in block.splitlines():
        command = shlex.split(line.split("  #")[0])
        if any(key in part for part in command for key in README_NOT_RUN):
            continue
        assert command[0] == ".venv/bin/python", line
        command = [sys.executable] + [part.replace("runs/", f"{tmp_path}/runs/") for part in command[1:]]
        for flag, value in README_SHORTENED.items():
            if flag in command:
                command[command.index(flag) + 1] = value
        if "--loop" in command:  # play.py: once through, not for ever
            command.remove("--loop")
        if command[1] == "scripts/reproduce.py" and code_commit().endswith("+dirty"):
            command.append("--allow-dirty")  # a checkout being edited (CI's fresh clone is clean)
        out = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=900,  # a slow, busy machine
                             env={**os.environ, "PYTHONUNBUFFERED": "1"})
        status = 0
        if command[1] == "scripts/reproduce.py":  # exit 1 when what ships fails its acceptance: its JSON says which
            status = 0 if json.loads(out.stdout.strip().splitlines()[-1])["passed"] else 1
        assert out.returncode == status, f"{line}\n{out.stderr[-2000:]}"
        assert "nan" not in out.stdout.lower().split(), line
        ran.append(command[1])
    assert ran.count("scripts/run_stack.py") == 4 and "scripts/play.py" in ran and "scripts/walk.py" in ran


@pytest.mark.unit
def test_parallel_jobs_go_through_the_execution_backend():
    """README: ``rabbit_policy/parallel.py`` is the execution backend of every parallel job; no
    script starts a pool of its own, and each that takes ``--workers`` for walks takes
    ``--backend`` too (the benchmarks of other things aside)."""
    for name in SCRIPTS:
        shim = (ROOT / "scripts" / f"{name}.py").read_text()
        module = re.search(r"^from (rabbit_\w+)\.commands\.(\w+) import main$", shim, re.M)
        assert module, f"scripts/{name}.py is not a shim over a commands module"
        source = (ROOT / "src" / module[1] / module[1] / "commands" / f"{module[2]}.py").read_text()
        assert "get_context(" not in source and "Pool(" not in source, f"{name}.py starts its own pool"
        every, _ = script_options(name)
        if "--workers" in every and not name.startswith("bench_stack"):
            assert "--backend" in every, f"{name}.py takes --workers but not --backend"


@pytest.mark.unit
def test_every_test_the_docs_name_exists():
    """docs/faults.md and the others cite tests by file and by name: both exist."""
    defined = {m for p in (ROOT / "tests").rglob("test_*.py")
               for m in re.findall(r"^def (test_\w+)\(", p.read_text(), re.M)}
    missing = []
    for doc in DOCS:
        text = doc.read_text()
        missing += [f"{doc.name}: {p}" for p in re.findall(r"\btests/[\w/]+\.py", text) if not (ROOT / p).is_file()]
        missing += [f"{doc.name}: {name}" for name in re.findall(r"`(test_\w+)`", text) if name not in defined]
    assert not missing, missing


@pytest.mark.unit
def test_the_module_map_lists_every_script_and_no_other():
    """architecture.md's module map names each ``scripts/*.py`` (the benchmarks as ``bench_*.py``)."""
    lines = (ROOT / "docs/architecture.md").read_text().splitlines()
    row = next(line for line in lines if line.startswith("| `scripts/` |"))
    listed = set(re.findall(r"`(\w+)\.py`", row))
    present = {p.stem for p in (ROOT / "scripts").glob("*.py")}
    assert listed - present == set(), f"README names scripts that do not exist: {listed - present}"
    missing = {name for name in present - listed if not name.startswith("bench_")}
    assert not missing, f"README's scripts row omits {sorted(missing)}"
    assert "`bench_*.py`" in row


HEADLINE_BEGIN = "<!-- headline table: rendered from docs/results/results.json"
HEADLINE_END = "<!-- end of headline table -->"


@pytest.mark.unit
def test_every_quoted_results_table_is_the_one_rendered_from_the_committed_results():
    """README's and results.md's results table is :func:`headline_table` of the committed
    ``results.json`` (``evaluate.py`` writes it as ``headline.md``), to the character."""
    import json

    from rabbit_policy.evaluation.report import headline_table

    results = json.loads((ROOT / "docs" / "results" / "results.json").read_text())
    rendered = "\n".join(headline_table(results))
    assert (ROOT / "docs" / "results" / "headline.md").read_text().strip() == rendered
    quoting = [doc for doc in DOCS if HEADLINE_BEGIN in doc.read_text()]
    assert {d.name for d in quoting} >= {"README.md", "results.md"}
    for doc in quoting:
        text = doc.read_text()
        block = text.split(HEADLINE_BEGIN, 1)[1].split("-->", 1)[1].split(HEADLINE_END, 1)[0].strip()
        assert block == rendered, f"{doc.name}'s results table differs from docs/results/headline.md"


@pytest.mark.unit
def test_every_figure_the_status_page_quotes_is_in_the_report_or_the_research_log():
    """docs/status.md quotes, never computes: each p-value it gives is written so in the
    committed report, results.md or the research log (issue 73: hand-copied figures drifted;
    its table is checked to the character above)."""
    import re

    status = (ROOT / "docs" / "status.md").read_text()
    sources = "\n".join((ROOT / "docs" / name).read_text() for name in ("results/report.md", "results.md",
                                                                        "learning.md"))
    quoted = set(re.findall(r"p = [0-9][0-9.e-]*[0-9]", status))
    assert len(quoted) >= 5, quoted  # (the page quotes them: the test reads it)
    missing = sorted(p for p in quoted if p not in sources)
    assert not missing, f"status.md quotes p-values no committed report or log holds: {missing}"


@pytest.mark.sim
def test_the_gymnasium_quickstart_runs_as_written():
    text = (ROOT / "docs" / "learning.md").read_text()
    block = re.search(r"## Gymnasium quickstart.*?```python\n(.*?)```", text, re.S).group(1)
    run = subprocess.run([sys.executable, "-c", block], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert run.returncode == 0, run.stderr[-2000:]
    assert re.fullmatch(r"\d+ steps, return -?\d+\.\d\d, walked at -?\d\.\d\d m/s for \d\.\d\d\n", run.stdout), run.stdout


@pytest.mark.unit
def test_the_docs_count_the_gaits_the_library_ships():
    """Every "N periodic gaits" in the docs is the packaged library's count."""
    gaits = len(list((ROOT / "src/rabbit_policy/rabbit_policy/gaits").glob("gait_*.json")))
    for doc in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        for count in re.findall(r"(\d+) periodic gaits", doc.read_text()):
            assert int(count) == gaits, (doc.name, count, gaits)


@pytest.mark.unit
def test_every_image_under_docs_is_shown_where_it_is_explained():
    """No orphan figure: every image under docs/ is linked from a Markdown page."""
    pages = " ".join(p.read_text() for p in [ROOT / "README.md", *(ROOT / "docs").rglob("*.md")])
    images = [p for p in (ROOT / "docs").rglob("*") if p.suffix in (".png", ".gif", ".jpg", ".svg")]
    assert images and [p.relative_to(ROOT) for p in images if p.name not in pages] == []
