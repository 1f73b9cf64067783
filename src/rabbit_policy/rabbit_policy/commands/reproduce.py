"""``scripts/reproduce.py --preset NAME --out DIR``: one command from a preset to a shipped
learned controller, everything under ``DIR`` (never into the package):

1. **train**, once per seed of the preset's ``seeds``: ``scripts/train.py --algo es --spec
   START --seed N`` with the preset's options: ES on the start spec's network in its deployed
   loop (``DIR/seed-N/run``). ``start: zero`` is the packaged learned spec with its network
   restarted from the seed (fresh hidden layers, a zero last layer: its rules on the library
   alone; ``DIR/seed-N/start.yaml``), ``calibrated`` the same with its feed-forward table
   re-measured on itself (:func:`~rabbit_policy.evaluation.steady_integral.calibrate_spec`:
   the rules at their best before training), ``packaged`` the packaged spec, else a spec file. Each
   run evaluates the acceptance checks every ``eval_every`` generations: its held-out
   learning curve (``DIR/curves.png``, every seed);
2. **screen**: the start, the packaged learned controller (when it is not the start) and each
   seed's ``screen.candidates`` evaluated specs (``screen.select``: ``acceptance``, those its
   acceptance ranks best; ``heldout``, those that pass most of the held-out selection trials
   among those no family of which is significantly worse there than the start's,
   :meth:`~rabbit_policy.evaluation.shipping.ScreenTrials.selection`, none of them the screen's;
   no evaluated spec: its last ``policy.yaml``), each on the acceptance checks (``evaluation``: ``quick`` or ``full``) and
   the paired screen trials (:mod:`rabbit_policy.evaluation.shipping`; ``screen.trials``:
   ``quick`` or ``full``), ``DIR/screen.json``; the candidate with most trials passed is
   chosen, and it ships only on a significant improvement over the start (McNemar's exact
   test, Bonferroni over the candidates screened: :func:`~rabbit_policy.evaluation.shipping.verdict`;
   with ``heldout`` the candidate judged is the one that ranks best on the selection trials, chosen
   off the screen, so no correction: :func:`selected_best`);
3. **ship**: the chosen candidate if it ships, else the start, as ``DIR/learned.yaml``, with
   its provenance (the code's commit, the gait library's hash, the preset, the verdict and
   the commands that ran);
4. **evaluate**: its measurements (``DIR/evaluation.json``);
5. **model card**: ``DIR/MODEL_CARD.md``, from the spec and its evaluation; its regenerate
   line is the command that ran (paths as ``$OUT`` and relative to the repository).

The last lines say one verdict (the console's ``verdict:`` line, the JSON's ``passed`` and
``beats_start``, the card's "Shipped" and "Acceptance"); the exit status is 0 when what ships
passes its acceptance checks, 1 when it fails them (or a training failed), 2 for bad arguments,
128 + the signal when a training was interrupted (Ctrl-C, SIGTERM: ``--resume`` continues it).

Presets are data (``config/reproduce/NAME.yaml``: ``start``, ``seeds``, ``train``,
``screen``, ``evaluation``, every key required; the seed is ``seeds``', not ``train``'s).
``--resume`` continues an interrupted run in ``DIR`` (``train.py --resume`` per seed: a
finished training trains no further) and screens it again. ``walk.py --spec
DIR/learned.yaml`` walks the result; ``run_stack.py`` and ``policy_node`` run it the same way."""

from __future__ import annotations

import json
import os
import shlex
import shutil
import sys
from pathlib import Path

from rabbit_msgs_py.cli import yaml_problem
from rabbit_policy.evaluation.statistics import format_rate

PRESET_KEYS = ("start", "seeds", "train", "screen", "evaluation")
SCREEN_KEYS = ("candidates", "trials", "select")
EVALUATIONS = ("quick", "full")
SELECTIONS = ("acceptance", "heldout")
STARTS = ("zero", "calibrated", "packaged")


def write_start(start: str, seed: int, path: Path) -> Path:
    """The start spec of a preset's ``start`` for ``seed``: ``zero`` and ``calibrated``
    written as ``path`` (once: an existing file is kept, so ``--resume`` trains on the same
    start), ``packaged`` the packaged learned spec, else the spec file ``start``."""
    from rabbit_policy.spec import packaged_spec

    if start not in ("zero", "calibrated"):
        return packaged_spec("learned") if start == "packaged" else Path(start).resolve()
    if not path.is_file():
        from rabbit_policy.learning.trained_specs import restarted_spec

        scratch = path.with_name(path.stem + ".partial.yaml")
        restarted_spec(packaged_spec("learned"), seed, scratch)
        if start == "calibrated":
            from rabbit_policy.evaluation.steady_integral import calibrate_spec

            calibrate_spec(scratch)
        scratch.replace(path)
    return path


def preset_dir() -> Path:
    return Path(__file__).resolve().parents[4] / "config" / "reproduce"


def load_preset(name: str) -> dict:
    """The preset ``name`` (``config/reproduce/NAME.yaml``) or the YAML file ``name``;
    ``ValueError`` with one line for a missing one or a wrong key."""
    import yaml

    path = Path(name) if name.endswith((".yaml", ".yml")) else preset_dir() / f"{name}.yaml"
    if not path.is_file():
        known = sorted(p.stem for p in preset_dir().glob("*.yaml"))
        raise ValueError(f"no preset {name!r} (known: {', '.join(known)}, or a .yaml file)")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ValueError(f"preset {path} is not YAML: {yaml_problem(exc)}") from None
    if not isinstance(data, dict) or set(data) != set(PRESET_KEYS):
        raise ValueError(f"preset {path} must have exactly the keys {', '.join(PRESET_KEYS)}")
    if not isinstance(data["train"], dict) or data["evaluation"] not in EVALUATIONS:
        raise ValueError(f"preset {path}: train is a mapping of train.py options, evaluation one of {EVALUATIONS}")
    if "seed" in data["train"]:
        raise ValueError(f"preset {path}: the seeds are the preset's seeds, not train's seed")
    seeds = data["seeds"]
    if (not isinstance(seeds, list) or not seeds or len(set(seeds)) != len(seeds)
            or any(not isinstance(s, int) or isinstance(s, bool) or s < 0 for s in seeds)):
        raise ValueError(f"preset {path}: seeds is a list of distinct whole numbers >= 0")
    if not isinstance(data["start"], str) or not (data["start"] in STARTS or data["start"].endswith((".yaml", ".yml"))):
        raise ValueError(f"preset {path}: start is one of {STARTS} or a spec file (.yaml)")
    screen = data["screen"]
    if (not isinstance(screen, dict) or set(screen) != set(SCREEN_KEYS) or screen["trials"] not in EVALUATIONS
            or not isinstance(screen["candidates"], int) or isinstance(screen["candidates"], bool)
            or screen["candidates"] < 1 or screen["select"] not in SELECTIONS):
        raise ValueError(f"preset {path}: screen is {{candidates: a whole number >= 1 per seed, trials: one of "
                         f"{EVALUATIONS}, select: one of {SELECTIONS}}}")
    return {**data, "path": str(path)}


def portable(text: str, out: Path, root: Path) -> str:
    """``text`` (a path or a command line) without this machine's paths, for a provenance that
    reads the same wherever it was made: the output directory as ``$OUT``, paths in the
    repository relative to it."""
    for path in sorted({str(out.resolve()), str(out)}, key=len, reverse=True):
        text = text.replace(path, "$OUT")
    return text.replace(str(root.resolve()) + os.sep, "")


def train_arguments(options: dict) -> list[str]:
    """A preset's ``train`` mapping as ``scripts/train.py`` arguments (``flag: true`` as the flag)."""
    argv: list[str] = []
    for key, value in options.items():
        flag = "--" + key.replace("_", "-")
        if value is True:
            argv.append(flag)
        elif value is not False:
            argv += [flag, str(value)]
    return argv


def _number_text(value) -> str:
    return "[" + ", ".join(f"{v:g}" for v in value) + "]" if isinstance(value, tuple) else f"{value:g}"


def _seconds(value: float | None) -> str:
    return "never" if value is None else f"{value:.3f}"


def model_card(spec, evaluation: dict, screen: list[dict], provenance: dict) -> str:
    """The model card of a reproduced learned controller: what it is, how it did, how it was
    chosen, how to rebuild it."""
    net = spec.network
    accepted = evaluation["acceptance"]
    rows = "\n".join(f"| {c['speed']:.2f} | {c['mean_speed_last']:.3f} | {c['error']:+.3f} | "
                     f"{'yes' if c['passed'] else 'no'} |" if c["mean_speed_last"] is not None
                     else f"| {c['speed']:.2f} | fell | | no |" for c in accepted["constant"])
    segments = "\n".join(f"| {s['command']:.2f} | {_seconds(s['reach_time'])} | {'yes' if s['passed'] else 'no'} |"
                         for s in accepted["schedule"]["segments"])
    stages = [f"gait library `{spec.gait_library.source}` ({spec.gait_library.mode}, sha256 "
              f"{spec.gait_library.sha256[:12]})",
              f"decisions every {spec.decision.period_ticks} ticks (1 ms)",
              f"network {net.inputs} -> {' -> '.join(map(str, net.hidden))} -> {net.outputs} ({net.output}; "
              f"features `{net.features}`; weights `{net.weights.file}`)"]
    if spec.speed_integral is not None:
        stages.insert(2, f"speed integral, gain {spec.speed_integral.gain:g} 1/s"
                         + (", feed-forward table" if spec.speed_integral.feedforward is not None else ""))
    if net.residual is not None:
        stages.append(f"a residual on the library's gait (scale {net.residual.scale[0]:g} rad, "
                      f"Kd {net.residual.scale[-1]:g} N m s/rad)")
    if spec.overlay is not None:
        stages.append(f"the recovery rule on top (offsets {list(spec.recovery_rule.offsets)} rad), the network's "
                      f"gaits blended over {spec.blend.length:g} of phase")
    families = ("forward", "backward", "changes")
    screened = "\n".join(f"| {row['candidate']} | {row['failures']} | "
                         + " | ".join(format_rate(row["rates"][f]) for f in families)
                         + f" | {row['passed']}/{row['of']} | " + _test_cell(row.get("against_start")) + " |"
                         for row in screen)
    verdict = provenance["verdict"]
    return "\n".join([
        f"# Model card: {spec.name} (reproduced)", "",
        "A learned HZD-RL controller written by `scripts/reproduce.py` (docs/controller_spec.md): the spec "
        "`learned.yaml` beside this card names every stage and constant; `walk.py --spec learned.yaml` walks it.", "",
        "## Stages", "", *[f"- {s}" for s in stages],
        "- the 1 kHz controller: " + ", ".join(f"{k} {_number_text(v)}" for k, v in spec.controller.settings().items())
        + f" (robot model sha256 {spec.controller.model_sha256[:12]})", "",
        f"## Acceptance ({provenance['evaluation']} criteria): {'passed' if accepted['passed'] else 'failed'}, "
        f"{accepted['failures']} failed checks", "",
        "| command (m/s) | mean speed | error | passed |", "|---|---|---|---|", rows, "",
        "| segment command (m/s) | reached in (s) | passed |", "|---|---|---|", segments, "",
        "## Screen", "",
        f"Paired trials ({provenance['screen_trials']}; `rabbit_policy.evaluation.shipping`): pushes scaled to "
        "classic's margins forward and backward, and command changes between speeds off the library's grid; "
        "every candidate walks the same trials. `start` is the spec training started from; McNemar's exact test "
        "against it, on all trials.", "",
        "| candidate | failed checks | forward pushes | backward pushes | changes | all | against the start |",
        "|---|---|---|---|---|---|---|", screened, "",
        *([f"Over the seeds (rliable: the interquartile mean of the trained candidates, a 95 % bootstrap "
           f"interval): screen trials passed {seeds['share']['iqm']:.3f} [{seeds['share']['ci95'][0]:.3f}, "
           f"{seeds['share']['ci95'][1]:.3f}] against the start's {seeds['start_share']:.3f}; the paired gain "
           f"over the start {seeds['gain_over_start']['iqm']:+.3f} [{seeds['gain_over_start']['ci95'][0]:+.3f}, "
           f"{seeds['gain_over_start']['ci95'][1]:+.3f}].", ""] if (seeds := verdict.get("over_seeds")) else []),
        f"**Shipped: `{provenance['shipped']}`.** The "
        + ("trained candidate that passed most held-out selection trials" if verdict.get("chosen_on") == "selection"
           else "best trained candidate") + f", `{provenance['screened']}`, is "
        f"significantly better than the start (p below {verdict['level']:.3g}, no family significantly worse, no "
        f"more failed checks): **{'yes' if verdict['ships'] else 'no'}**"
        + (", so it ships." if verdict["ships"] else "; " + "; ".join(verdict["why"]) + ", so the start ships."),
        "",
        "## Provenance", "",
        f"- code commit: {provenance['code_commit']}",
        f"- gait library sha256: {provenance['library_sha256']}",
        f"- preset: `{provenance['preset']}`; started from `{provenance['start']}`",
        f"- trained: ES, seeds {', '.join(str(r['seed']) for r in provenance['runs'])}: "
        + "; ".join(f"seed {r['seed']} {r['iterations']} generation(s), {r['env_steps']} env steps, {r['wall_s']} s"
                    for r in provenance["runs"]), "",
        "## Regenerate", "", "```", *provenance["commands"], "```", ""])


def _test_cell(test: dict | None) -> str:
    if test is None:
        return ""
    return f"+{test['only_a']} / -{test['only_b']}, p = {test['p_value']:.3g}"


def evaluated(run: Path) -> list[dict]:
    """The run's evaluated specs it kept, in training order: ``eval.csv``'s rows after the
    start's, each with its ``path`` (``evaluated/ITERATION.yaml``)."""
    import csv

    if not (run / "eval.csv").is_file():
        return []
    with open(run / "eval.csv") as stream:
        rows = [{**r, "path": run / "evaluated" / f"{int(r['iteration']):05d}.yaml"} for r in csv.DictReader(stream)]
    return [r for r in rows if int(r["iteration"]) > 0 and r["path"].is_file()]


def candidates(run: Path, count: int) -> list[Path]:
    """The run's candidate specs: the ``count`` evaluated ones its acceptance ranks best
    (``eval.csv``: fewest failed checks, then the smallest summed error; the start's row
    left out), else its last ``policy.yaml``."""
    rows = sorted(evaluated(run), key=lambda r: (int(r["failures"]), float(r["total_error"]), -int(r["iteration"])))
    return [r["path"] for r in rows[:count]] or [run / "policy.yaml"]


def selection_key(scored: dict) -> tuple:
    """Sort key of a snapshot's selection counts, lower is better: no family significantly worse
    than the start's on the selection trials (``worse`` empty), then most trials passed, then fewest
    failed acceptance checks, then the later (snapshots of two seeds that tie on all of it: the seed
    trained first)."""
    return (bool(scored.get("worse")), -scored["passed"], scored["failures"], -scored["iteration"])


def heldout_candidates(run: Path, count: int, trials, map_fn,
                       start: dict | None = None) -> tuple[list[Path], list[dict]]:
    """The run's candidate specs picked on held-out ``trials``: the ``count`` evaluated ones
    that rank best by :func:`selection_key`, else its last ``policy.yaml``; and each evaluated
    spec's counts (``candidate``, ``passed``, ``of``, ``rates``, ``failures``; with ``start``,
    the start's :func:`~rabbit_policy.evaluation.shipping.measure` on the same trials, also
    ``worse``: the families significantly worse than the start's), in training order."""
    from rabbit_policy.evaluation.shipping import family_tests, measure, worse_families
    from rabbit_policy.spec import load_controller

    scored = []
    for row in evaluated(run):
        counted = measure(load_controller(row["path"]), trials, map_fn)
        worse = worse_families(family_tests(counted, start)) if start is not None else []
        scored.append({"candidate": row["path"], "iteration": int(row["iteration"]), "failures": int(row["failures"]),
                       **{k: counted[k] for k in ("passed", "of", "rates")}, "worse": worse})
    ranked = sorted(scored, key=selection_key)
    return [r["candidate"] for r in ranked[:count]] or [run / "policy.yaml"], scored


def measure_candidate(path: Path, criteria, trials, map_fn) -> dict:
    """A spec's acceptance checks and screen trials (:func:`rabbit_policy.evaluation.shipping.measure`)."""
    from rabbit_policy.evaluation.acceptance import acceptance
    from rabbit_policy.evaluation.shipping import measure
    from rabbit_policy.spec import load_controller

    policy = load_controller(path)
    accepted = acceptance(policy, criteria, map_fn=map_fn)
    return {"failures": accepted["failures"], "acceptance": accepted, **measure(policy, trials, map_fn)}


def pick_candidates(out: Path, preset: dict, runs: list[dict], start: Path,
                    map_fn) -> tuple[list[tuple[str, Path]], dict]:
    """Each seed's ``screen.candidates`` specs as ``(name relative to out, path)``, picked as
    ``screen.select`` says; with ``heldout`` also each seed's selection counts against the
    ``start`` spec's on the same trials (:func:`heldout_candidates`), printed a line per seed."""
    from rabbit_policy.evaluation.shipping import ScreenTrials, measure
    from rabbit_policy.spec import load_controller

    count, picked, selection = preset["screen"]["candidates"], [], {}
    if preset["screen"]["select"] == "acceptance":
        return [(str(p.relative_to(out)), p) for r in runs for p in candidates(r["run"], count)], selection
    held_out = ScreenTrials.selection(quick=preset["screen"]["trials"] == "quick")
    start_counted = measure(load_controller(start), held_out, map_fn)
    selection["start"] = {k: start_counted[k] for k in ("passed", "of", "rates")}
    print(f"  select, the start: {start_counted['passed']}/{start_counted['of']} held-out trials passed", flush=True)
    for r in runs:
        paths, scored = heldout_candidates(r["run"], count, held_out, map_fn, start_counted)
        picked += [(str(p.relative_to(out)), p) for p in paths]
        selection[f"seed-{r['seed']}"] = [{**s, "candidate": str(s["candidate"].relative_to(out))} for s in scored]
        counts = ", ".join(f"{s['iteration']}: {s['passed']}/{s['of']}"
                           + (f" ({', '.join(s['worse'])} worse)" if s["worse"] else "") for s in scored)
        print(f"  select, seed {r['seed']}: {counts} held-out trials passed; "
              + ", ".join(str(p.relative_to(out)) for p in paths), flush=True)
    return picked, selection


def selected_best(selection: dict, names: list[str]) -> str | None:
    """Of the screened candidates ``names``, the one that ranks best on the held-out selection
    trials (:func:`selection_key`); None without a selection. The verdict judges it alone:
    chosen off the screen, no correction for a choice on it."""
    scored = [s for seed, rows in selection.items() if seed != "start" for s in rows if s["candidate"] in names]
    if not scored:
        return None
    return min(scored, key=selection_key)["candidate"]


def screen_candidates(screened: list[tuple[str, Path]], criteria, trials, map_fn) -> list[dict]:
    """Each named spec's acceptance checks and screen trials (:func:`measure_candidate`), every
    one after the first with its paired test against the first (the start), printed a line each."""
    from rabbit_policy.evaluation.shipping import pooled
    from rabbit_policy.evaluation.statistics import mcnemar_exact

    rows = []
    for name, path in screened:
        row = {"candidate": name, **measure_candidate(path, criteria, trials, map_fn)}
        if rows:
            row["against_start"] = mcnemar_exact(pooled(row), pooled(rows[0]))
        rows.append(row)
        print(f"  {name}: {row['failures']} failed checks, " + ", ".join(
            f"{f} {format_rate(r)}" for f, r in row["rates"].items()) + f", all {row['passed']}/{row['of']}", flush=True)
    return rows


def train_seeds(preset: dict, out: Path, root: Path, resume: bool, commands: list[str]) -> tuple[list, list] | int:
    """Step 1: each seed's start spec and training (``scripts/train.py``, its line appended to
    ``commands``), one after another; (the runs, the start specs), or the exit status when a
    training failed (1) or was interrupted (128 + the signal: ``--resume`` continues it)."""
    import signal
    import subprocess

    runs, starts = [], []
    for index, seed in enumerate(preset["seeds"]):
        seed_dir = out / f"seed-{seed}"
        seed_dir.mkdir(parents=True, exist_ok=True)
        start = write_start(preset["start"], seed, seed_dir / "start.yaml")
        starts.append(start)
        run = seed_dir / "run"
        train_argv = ["--algo", "es", "--spec", str(start), "--out", str(run), "--no-progress", "--seed", str(seed),
                      *train_arguments(preset["train"]),
                      *(["--resume"] if resume and (run / "checkpoint.pt").is_file() else [])]
        train_line = "scripts/train.py " + " ".join(shlex.quote(a) for a in train_argv)
        commands.append(train_line)
        print(f"[1/5] train, seed {seed} ({index + 1} of {len(preset['seeds'])}): {train_line}", flush=True)
        trained = subprocess.Popen([sys.executable, "-m", "rabbit_policy.commands.train", *train_argv], cwd=root)
        try:
            trained.wait()
        except KeyboardInterrupt:  # Ctrl-C reached the training too: it writes its checkpoint, then stops
            trained.wait()
        if trained.returncode in (128 + signal.SIGINT, 128 + signal.SIGTERM):  # a checkpoint was written
            print(f"interrupted: training seed {seed} stopped with its checkpoint; --resume continues it",
                  file=sys.stderr)
            return trained.returncode
        if trained.returncode != 0:
            print(f"error: training seed {seed} failed with status {trained.returncode} (its output is above; {run} "
                  "holds the run)", file=sys.stderr)
            return 1
        info = json.loads((run / "summary.json").read_text())["info"]
        runs.append({"seed": seed, "run": run, "iterations": info["iteration"], "env_steps": info["env_steps"],
                     "wall_s": info["wall_s"]})
    return runs, starts


def build_parser():
    from rabbit_msgs_py.cli import ArgumentParser
    from rabbit_policy.experiment.options import add_allow_dirty_option
    from rabbit_policy.parallel import add_backend_arguments

    parser = ArgumentParser(description=__doc__)
    parser.add_argument("--preset", required=True, help="config/reproduce/NAME.yaml (tiny, shipped, counted) or a .yaml file")
    parser.add_argument("--out", type=Path, required=True, help="a new directory for everything it writes")
    parser.add_argument("--resume", action="store_true", help="continue the runs in --out and screen them again")
    add_allow_dirty_option(parser)
    add_backend_arguments(parser, progress=False, workers=True)
    return parser


def main(argv: list[str] | None = None) -> int:
    from rabbit_msgs_py.cli import ensure_output_dir
    from rabbit_policy.spec.provenance import DirtyTree, shipping_provenance
    from rabbit_policy.parallel import open_backend

    parser = build_parser()
    args = parser.parse_args(argv)
    ensure_output_dir(parser, args.out)  # before any work: one line, exit 2
    try:
        preset = load_preset(args.preset)
        ran_on = shipping_provenance(args.allow_dirty, preset_dir().parents[1])  # before the training, not after
    except (ValueError, DirtyTree) as exc:
        parser.error(str(exc))
    out: Path = args.out
    if out.exists() and any(out.iterdir()) and not args.resume:
        print(f"error: {out} is not empty: give a new --out, or --resume", file=sys.stderr)
        return 2
    if args.resume and not any((out / f"seed-{s}" / "run" / "checkpoint.pt").is_file() for s in preset["seeds"]):
        print(f"error: --resume: {out} holds no training to continue", file=sys.stderr)
        return 2

    from dataclasses import replace

    from rabbit_msgs_py import strict_json
    from rabbit_policy.commands.plot_training import plot
    from rabbit_policy.evaluation.acceptance import Criteria
    from rabbit_policy.evaluation.shipping import ScreenTrials, over_seeds, screen_rank, verdict
    from rabbit_policy.spec import dump_spec, load_spec, packaged_spec
    from rabbit_policy.spec.files import library_dir, library_hash

    root = preset_dir().parents[1]
    reproduce_line = (f"scripts/reproduce.py --preset {shlex.quote(args.preset)} --out {shlex.quote(str(out))}"
                      + (f" --workers {args.workers}" if args.workers != 2 else "")
                      + (" --resume" if args.resume else ""))
    commands = [reproduce_line, "# which ran:"]
    trained = train_seeds(preset, out, root, args.resume, commands)
    if isinstance(trained, int):  # a training failed or was interrupted: its status
        return trained
    runs, starts = trained
    plot([(f"seed {r['seed']}", r["run"]) for r in runs], out / "curves.png")
    criteria = Criteria.quick() if preset["evaluation"] == "quick" else Criteria()
    trials = ScreenTrials.quick() if preset["screen"]["trials"] == "quick" else ScreenTrials()
    screened = [("start", starts[0])]
    if preset["start"] != "packaged":
        screened.append(("packaged", packaged_spec("learned")))
    backend = open_backend(parser, args)
    try:
        picked, selection = pick_candidates(out, preset, runs, starts[0], backend.map)
        screened += picked
        print(f"[2/5] screen: {', '.join(name for name, _ in screened)} (acceptance and {trials.count('forward')} + "
              f"{trials.count('backward')} pushes and {trials.count('changes')} changes, paired)", flush=True)
        rows = screen_candidates(screened, criteria, trials, backend.map)
    finally:
        backend.close()
    trained_rows = [r for r in rows if r["candidate"] not in ("start", "packaged")]
    on_selection = selected_best(selection, [r["candidate"] for r in trained_rows])
    best = (next(r for r in trained_rows if r["candidate"] == on_selection) if on_selection
            else min(trained_rows, key=screen_rank))
    ships, why, tests = verdict(best, rows[0], screened=1 if on_selection else len(trained_rows))
    chosen_name = best["candidate"] if ships else "start"
    chosen = dict(screened)[chosen_name]
    level = 0.05 / (1 if on_selection else len(trained_rows))
    seeds = over_seeds(trained_rows, rows[0])
    print(f"  over the {seeds['candidates']} seeds: screen passed IQM {seeds['share']['iqm']:.3f} "
          f"[{seeds['share']['ci95'][0]:.3f}, {seeds['share']['ci95'][1]:.3f}] (the start {seeds['start_share']:.3f}), "
          f"gain over the start IQM {seeds['gain_over_start']['iqm']:+.3f} [{seeds['gain_over_start']['ci95'][0]:+.3f}, "
          f"{seeds['gain_over_start']['ci95'][1]:+.3f}]", flush=True)
    (out / "screen.json").write_text(strict_json.dumps({
        "candidates": rows, "best": best["candidate"], "beats_start": ships, "why_not": why, "tests": tests,
        "level": level, "shipped": chosen_name, "over_seeds": seeds, "select": preset["screen"]["select"],
        "chosen_on": "selection" if on_selection else "screen", "selection": selection}, indent=2) + "\n")
    spec = load_spec(chosen)
    weights = chosen.parent / spec.network.weights.file
    shutil.copyfile(weights, out / weights.name)
    commands = [portable(c, out, root) for c in commands]
    provenance = {**ran_on, "preset": portable(preset["path"], out, root), "start": portable(preset["start"], out, root),
                  "library_sha256": library_hash(library_dir(spec.gait_library.source, chosen.parent)),
                  "runs": [{k: v for k, v in r.items() if k != "run"} for r in runs],
                  "evaluation": preset["evaluation"], "screen_trials": preset["screen"]["trials"],
                  "screened": best["candidate"], "shipped": chosen_name,
                  "verdict": {"ships": ships, "why": why, "level": level, "over_seeds": seeds,
                              "chosen_on": "selection" if on_selection else "screen"}, "commands": commands}
    shipped = replace(spec, provenance=provenance)
    dump_spec(shipped, out / "learned.yaml", f"{spec.name}, reproduced by {portable(reproduce_line, out, root)}")
    print(f"[3/5] ship: {out / 'learned.yaml'} ({chosen_name}; {best['candidate']} significantly better than the "
          f"start: {'yes' if ships else 'no'}" + ("" if ships else f": {'; '.join(why)}") + ")", flush=True)
    shipped_row = next(r for r in rows if r["candidate"] == chosen_name)
    evaluation = {k: shipped_row[k] for k in ("acceptance", "rates", "passed", "of")}
    (out / "evaluation.json").write_text(strict_json.dumps(evaluation, indent=2) + "\n")
    print(f"[4/5] evaluate: {out / 'evaluation.json'}", flush=True)
    (out / "MODEL_CARD.md").write_text(model_card(shipped, evaluation, rows, provenance))
    print(f"[5/5] model card: {out / 'MODEL_CARD.md'}", flush=True)
    passed = shipped_row["acceptance"]["passed"]
    print(f"verdict: ships {chosen_name}; its acceptance ({preset['evaluation']} criteria) "
          f"{'passed' if passed else 'FAILED'} ({shipped_row['failures']} failed checks); a trained candidate "
          f"significantly better than the start: {'yes' if ships else 'no'}", flush=True)
    print(strict_json.dumps({"out": str(out), "spec": str(out / "learned.yaml"), "shipped": chosen_name,
                             "passed": passed, "failures": shipped_row["failures"], "beats_start": ships}))
    return 0 if passed else 1
