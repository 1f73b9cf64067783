"""``scripts/reproduce.py --preset NAME --out DIR``: one command from a preset to a shipped
learned controller, everything under ``DIR`` (never into the package):

1. **train**: ``scripts/train.py --algo es --spec START`` with the preset's options: ES on the
   start spec's network in its deployed loop (``DIR/run``);
2. **screen**: the start spec and the run's candidates (the ``screen.candidates`` evaluated
   ones the training's acceptance ranks best, else its last ``policy.yaml``), each measured on
   the acceptance checks (``evaluation``: ``quick`` or ``full``), the paper's three push
   scenarios as ``evaluate.py`` walks them and the push grid scaled to classic's margins
   (:mod:`rabbit_policy.evaluation.shipping`; ``screen.grid``: ``quick`` or ``full``),
   ``DIR/screen.json``; the best candidate by :func:`~rabbit_policy.evaluation.shipping.screen_rank`
   is chosen, and the verdict says whether it beats the start (the bar for shipping it in
   the package);
3. **ship**: that spec and its weights as ``DIR/learned.yaml``, with its provenance (the code's
   commit, the gait library's hash, the preset, the verdict and the commands that ran);
4. **evaluate**: its measurements (``DIR/evaluation.json``);
5. **model card**: ``DIR/MODEL_CARD.md``, from the spec and its evaluation; its regenerate
   line is the command that ran.

Presets are data (``config/reproduce/NAME.yaml``: ``start``, ``train``, ``screen``,
``evaluation``, every key required). ``--resume`` continues an interrupted run in ``DIR``
(``train.py --resume``: a finished training trains no further) and screens it again. ``walk.py --controller learned --policy-file DIR/learned.yaml`` walks the
result; ``run_stack.py`` and ``policy_node`` run it the same way."""

from __future__ import annotations

import json
import shlex
import shutil
import sys
from pathlib import Path

PRESET_KEYS = ("start", "train", "screen", "evaluation")
SCREEN_KEYS = ("candidates", "grid")
EVALUATIONS = ("quick", "full")


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
    data = yaml.safe_load(path.read_text())
    if not isinstance(data, dict) or set(data) != set(PRESET_KEYS):
        raise ValueError(f"preset {path} must have exactly the keys {', '.join(PRESET_KEYS)}")
    if not isinstance(data["train"], dict) or data["evaluation"] not in EVALUATIONS:
        raise ValueError(f"preset {path}: train is a mapping of train.py options, evaluation one of {EVALUATIONS}")
    screen = data["screen"]
    if (not isinstance(screen, dict) or set(screen) != set(SCREEN_KEYS) or screen["grid"] not in EVALUATIONS
            or not isinstance(screen["candidates"], int) or isinstance(screen["candidates"], bool)
            or screen["candidates"] < 1):
        raise ValueError(f"preset {path}: screen is {{candidates: a whole number >= 1, grid: one of {EVALUATIONS}}}")
    return {**data, "path": str(path)}


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
    names = list(evaluation["scenarios"])
    grid = evaluation["margin_grid"]
    screened = "\n".join(f"| {row['candidate']} | {row['failures']} | "
                         + " | ".join(row["scenarios"][n]["outcome"] for n in names)
                         + f" | {row['margin_grid']['forward']} | {row['margin_grid']['backward']} |" for row in screen)
    verdict = provenance["verdict"]
    return "\n".join([
        f"# Model card: {spec.name} (reproduced)", "",
        "A learned HZD-RL controller written by `scripts/reproduce.py` (docs/controller_spec.md): the spec "
        "`learned.yaml` beside this card names every stage and constant; `walk.py --controller learned "
        "--policy-file learned.yaml` walks it.", "",
        "## Stages", "", *[f"- {s}" for s in stages],
        f"- the 1 kHz controller: {', '.join(f'{k} {v:g}' for k, v in vars(spec.controller).items())}", "",
        f"## Acceptance ({provenance['evaluation']} criteria): {'passed' if accepted['passed'] else 'failed'}, "
        f"{accepted['failures']} failed checks", "",
        "| command (m/s) | mean speed | error | passed |", "|---|---|---|---|", rows, "",
        "| segment command (m/s) | reached in (s) | passed |", "|---|---|---|", segments, "",
        "## Screen", "",
        f"Pushes: the paper's three scenarios as `evaluate.py` walks them, and a grid of single pushes scaled to "
        f"classic's margins ({provenance['screen_grid']}: {grid['of']['forward']} per direction; "
        "`rabbit_policy.evaluation.shipping`). `start` is the spec training started from.", "",
        "| candidate | failed checks | " + " | ".join(names) + " | forward pushes | backward pushes |",
        "|---|---|" + "---|" * len(names) + "---|---|", screened, "",
        f"Chosen: `{provenance['screened']}`. Beats the start (fails no more checks, walks every scenario the start "
        f"walks and large_backward, more forward pushes, no fewer backward): **{'yes' if verdict['ships'] else 'no'}**"
        + ("" if verdict["ships"] else "; " + "; ".join(verdict["why"])), "",
        "## Provenance", "",
        f"- code commit: {provenance['code_commit']}",
        f"- gait library sha256: {provenance['library_sha256']}",
        f"- preset: `{provenance['preset']}`; started from `{provenance['start']}`",
        f"- trained: ES, {provenance['iterations']} generation(s), {provenance['env_steps']} env steps, "
        f"{provenance['wall_s']} s", "",
        "## Regenerate", "", "```", *provenance["commands"], "```", ""])


def candidates(run: Path, count: int) -> list[Path]:
    """The run's candidate specs: the ``count`` evaluated ones its acceptance ranks best
    (``eval.csv``: fewest failed checks, then the smallest summed error; the start's row
    left out), else its last ``policy.yaml``."""
    import csv

    rows = []
    if (run / "eval.csv").is_file():
        with open(run / "eval.csv") as stream:
            rows = [r for r in csv.DictReader(stream) if int(r["iteration"]) > 0
                    and (run / "evaluated" / f"{int(r['iteration']):05d}.yaml").is_file()]
    rows.sort(key=lambda r: (int(r["failures"]), float(r["total_error"]), -int(r["iteration"])))
    chosen = [run / "evaluated" / f"{int(r['iteration']):05d}.yaml" for r in rows[:count]]
    return chosen or [run / "policy.yaml"]


def measure_candidate(path: Path, criteria, grid, map_fn) -> dict:
    """A spec's acceptance checks and pushes (:func:`rabbit_policy.evaluation.shipping.measure`)."""
    from rabbit_policy.evaluation.acceptance import acceptance
    from rabbit_policy.evaluation.shipping import measure
    from rabbit_policy.spec import load_controller

    policy = load_controller(path)
    accepted = acceptance(policy, criteria, map_fn=map_fn)
    return {"failures": accepted["failures"], "acceptance": accepted, **measure(policy, grid, map_fn)}


def main(argv: list[str] | None = None) -> int:
    from rabbit_msgs_py.cli import ArgumentParser
    from rabbit_policy.experiment.options import add_allow_dirty_option
    from rabbit_policy.experiment.provenance import DirtyTree, shipping_provenance
    from rabbit_policy.parallel import add_backend_arguments, open_backend

    parser = ArgumentParser(description=__doc__)
    parser.add_argument("--preset", required=True, help="config/reproduce/NAME.yaml (tiny, shipped) or a .yaml file")
    parser.add_argument("--out", type=Path, required=True, help="a new directory for everything it writes")
    parser.add_argument("--resume", action="store_true", help="continue the run in --out and screen it again")
    add_allow_dirty_option(parser)
    add_backend_arguments(parser, progress=False, workers=True)
    args = parser.parse_args(argv)
    try:
        preset = load_preset(args.preset)
        ran_on = shipping_provenance(args.allow_dirty, preset_dir().parents[1])  # before the training, not after
    except (ValueError, DirtyTree) as exc:
        parser.error(str(exc))
    out: Path = args.out
    if out.exists() and any(out.iterdir()) and not args.resume:
        print(f"error: {out} is not empty: give a new --out, or --resume", file=sys.stderr)
        return 2
    if args.resume and not (out / "run" / "checkpoint.pt").is_file():
        print(f"error: --resume: {out / 'run'} holds no training to continue", file=sys.stderr)
        return 2

    import subprocess
    from dataclasses import replace

    from rabbit_msgs_py import strict_json
    from rabbit_policy.evaluation.acceptance import Criteria
    from rabbit_policy.evaluation.shipping import MarginGrid, screen_rank, verdict
    from rabbit_policy.spec import dump_spec, load_spec, packaged_spec
    from rabbit_policy.spec.files import library_dir, library_hash

    root = preset_dir().parents[1]
    start = packaged_spec("learned") if preset["start"] == "packaged" else Path(preset["start"]).resolve()
    run = out / "run"
    train_argv = ["--algo", "es", "--spec", str(start), "--out", str(run), "--no-progress",
                  *train_arguments(preset["train"]), *(["--resume"] if args.resume else [])]
    reproduce_line = (f"scripts/reproduce.py --preset {shlex.quote(args.preset)} --out {shlex.quote(str(out))}"
                      + (f" --workers {args.workers}" if args.workers != 2 else "")
                      + (" --resume" if args.resume else ""))
    train_line = "scripts/train.py " + " ".join(shlex.quote(a) for a in train_argv)
    print(f"[1/5] train: {train_line}", flush=True)
    trained = subprocess.run([sys.executable, "-m", "rabbit_policy.commands.train", *train_argv], cwd=root)
    if trained.returncode != 0:
        print(f"error: training failed with status {trained.returncode} (its output is above; {run} holds the run)",
              file=sys.stderr)
        return 1
    criteria = Criteria.quick() if preset["evaluation"] == "quick" else Criteria()
    grid = MarginGrid.quick() if preset["screen"]["grid"] == "quick" else MarginGrid()
    screened = [("start", start), *((str(p.relative_to(out)), p)
                                    for p in candidates(run, preset["screen"]["candidates"]))]
    print(f"[2/5] screen: {', '.join(name for name, _ in screened)} (acceptance, the paper's push scenarios, "
          f"the {preset['screen']['grid']} push grid)", flush=True)
    rows = []
    backend = open_backend(parser, args)
    try:
        for name, path in screened:
            rows.append({"candidate": name, **measure_candidate(path, criteria, grid, backend.map)})
            row = rows[-1]
            print(f"  {name}: {row['failures']} failed checks, scenarios "
                  f"{', '.join(o['outcome'] for o in row['scenarios'].values())}, pushes forward "
                  f"{row['margin_grid']['forward']} backward {row['margin_grid']['backward']} of "
                  f"{row['margin_grid']['of']['forward']}", flush=True)
    finally:
        backend.close()
    best = min(rows[1:], key=screen_rank)
    ships, why = verdict(best, rows[0])
    chosen = dict(screened)[best["candidate"]]
    (out / "screen.json").write_text(strict_json.dumps({"candidates": rows, "chosen": best["candidate"],
                                                        "beats_start": ships, "why_not": why}, indent=2) + "\n")
    spec = load_spec(chosen)
    summary = json.loads((run / "summary.json").read_text())["info"]
    weights = chosen.parent / spec.network.weights.file
    shutil.copyfile(weights, out / weights.name)
    provenance = {**ran_on, "preset": preset["path"], "start": str(start),
                  "library_sha256": library_hash(library_dir(spec.gait_library.source, chosen.parent)),
                  "iterations": summary["iteration"], "env_steps": summary["env_steps"], "wall_s": summary["wall_s"],
                  "evaluation": preset["evaluation"], "screen_grid": preset["screen"]["grid"],
                  "screened": best["candidate"], "verdict": {"ships": ships, "why": why},
                  "commands": [reproduce_line, "# which ran:", train_line]}
    shipped = replace(spec, provenance=provenance)
    dump_spec(shipped, out / "learned.yaml", f"{spec.name}, reproduced by {reproduce_line}")
    print(f"[3/5] ship: {out / 'learned.yaml'} ({best['candidate']}; beats the start: {'yes' if ships else 'no'}"
          + ("" if ships else f": {'; '.join(why)}") + ")", flush=True)
    evaluation = {k: best[k] for k in ("acceptance", "scenarios", "margin_grid")}
    (out / "evaluation.json").write_text(strict_json.dumps(evaluation, indent=2) + "\n")
    print(f"[4/5] evaluate: {out / 'evaluation.json'}", flush=True)
    (out / "MODEL_CARD.md").write_text(model_card(shipped, evaluation, rows, provenance))
    print(f"[5/5] model card: {out / 'MODEL_CARD.md'}", flush=True)
    print(strict_json.dumps({"out": str(out), "spec": str(out / "learned.yaml"),
                             "passed": best["acceptance"]["passed"], "failures": best["failures"],
                             "beats_start": ships}))
    return 0
