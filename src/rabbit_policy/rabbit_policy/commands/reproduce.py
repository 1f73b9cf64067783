"""``scripts/reproduce.py --preset NAME --out DIR``: one command from a preset to a shipped
learned controller, everything under ``DIR`` (never into the package):

1. **train**: ``scripts/train.py --algo es --spec START`` with the preset's options: ES on the
   start spec's network in its deployed loop (``DIR/run``);
2. **screen**: the run's ``best.yaml`` (the best evaluated candidate by the acceptance checks),
   else its last ``policy.yaml``;
3. **ship**: that spec and its weights as ``DIR/learned.yaml``, with its provenance (the code's
   commit, the gait library's hash, the preset and the commands that ran);
4. **evaluate**: the acceptance checks on it (``DIR/evaluation.json``; ``quick`` or ``full``);
5. **model card**: ``DIR/MODEL_CARD.md``, from the spec and its evaluation; its regenerate
   line is the command that ran.

Presets are data (``config/reproduce/NAME.yaml``: ``start``, ``train``, ``evaluation``, every
key required). ``walk.py --controller learned --policy-file DIR/learned.yaml`` walks the
result; ``run_stack.py`` and ``policy_node`` run it the same way."""

from __future__ import annotations

import json
import shlex
import shutil
import sys
from pathlib import Path

PRESET_KEYS = ("start", "train", "evaluation")
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


def model_card(spec, evaluation: dict, provenance: dict) -> str:
    """The model card of a reproduced learned controller: what it is, how it did, how to rebuild it."""
    net = spec.network
    rows = "\n".join(f"| {c['speed']:.2f} | {c['mean_speed_last']:.3f} | {c['error']:+.3f} | "
                     f"{'yes' if c['passed'] else 'no'} |" if c["mean_speed_last"] is not None
                     else f"| {c['speed']:.2f} | fell | | no |" for c in evaluation["constant"])
    segments = "\n".join(f"| {s['command']:.2f} | {_seconds(s['reach_time'])} | {'yes' if s['passed'] else 'no'} |"
                         for s in evaluation["schedule"]["segments"])
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
    return "\n".join([
        f"# Model card: {spec.name} (reproduced)", "",
        "A learned HZD-RL controller written by `scripts/reproduce.py` (docs/controller_spec.md): the spec "
        "`learned.yaml` beside this card names every stage and constant; `walk.py --controller learned "
        "--policy-file learned.yaml` walks it.", "",
        "## Stages", "", *[f"- {s}" for s in stages],
        f"- the 1 kHz controller: {', '.join(f'{k} {v:g}' for k, v in vars(spec.controller).items())}", "",
        f"## Acceptance ({provenance['evaluation']} criteria): {'passed' if evaluation['passed'] else 'failed'}, "
        f"{evaluation['failures']} failed checks", "",
        "| command (m/s) | mean speed | error | passed |", "|---|---|---|---|", rows, "",
        "| segment command (m/s) | reached in (s) | passed |", "|---|---|---|", segments, "",
        "## Provenance", "",
        f"- code commit: {provenance['code_commit']}",
        f"- gait library sha256: {provenance['library_sha256']}",
        f"- preset: `{provenance['preset']}`; started from `{provenance['start']}`",
        f"- trained: ES, {provenance['iterations']} generation(s), {provenance['env_steps']} env steps, "
        f"{provenance['wall_s']} s", "",
        "## Regenerate", "", "```", *provenance["commands"], "```", ""])


def main(argv: list[str] | None = None) -> int:
    from rabbit_msgs_py.cli import ArgumentParser

    parser = ArgumentParser(description=__doc__)
    parser.add_argument("--preset", required=True, help="config/reproduce/NAME.yaml (tiny, shipped) or a .yaml file")
    parser.add_argument("--out", type=Path, required=True, help="a new directory for everything it writes")
    args = parser.parse_args(argv)
    try:
        preset = load_preset(args.preset)
    except ValueError as exc:
        parser.error(str(exc))
    out: Path = args.out
    if out.exists() and any(out.iterdir()):
        print(f"error: {out} is not empty: give a new --out", file=sys.stderr)
        return 2

    import subprocess

    from rabbit_msgs_py import strict_json
    from rabbit_policy.evaluation.acceptance import Criteria, acceptance
    from rabbit_policy.spec import dump_spec, load_spec, packaged_spec
    from rabbit_policy.spec.build import build
    from rabbit_policy.spec.convert import code_commit
    from rabbit_policy.spec.files import library_dir, library_hash

    root = preset_dir().parents[1]
    start = packaged_spec("learned") if preset["start"] == "packaged" else Path(preset["start"]).resolve()
    run = out / "run"
    train_argv = ["--algo", "es", "--spec", str(start), "--out", str(run), "--no-progress",
                  *train_arguments(preset["train"])]
    reproduce_line = f"scripts/reproduce.py --preset {shlex.quote(args.preset)} --out {shlex.quote(str(out))}"
    train_line = "scripts/train.py " + " ".join(shlex.quote(a) for a in train_argv)
    print(f"[1/5] train: {train_line}", flush=True)
    trained = subprocess.run([sys.executable, "-m", "rabbit_policy.commands.train", *train_argv], cwd=root)
    if trained.returncode != 0:
        print(f"error: training failed with status {trained.returncode} (its output is above; {run} holds the run)",
              file=sys.stderr)
        return 1
    chosen = run / "best.yaml" if (run / "best.yaml").is_file() else run / "policy.yaml"
    print(f"[2/5] screen: {chosen.relative_to(out)} (the best evaluated candidate, else the last)", flush=True)
    spec = load_spec(chosen)
    summary = json.loads((run / "summary.json").read_text())["info"]
    weights = chosen.parent / spec.network.weights.file
    shutil.copyfile(weights, out / weights.name)
    provenance = {"code_commit": code_commit(root), "preset": preset["path"], "start": str(start),
                  "library_sha256": library_hash(library_dir(spec.gait_library.source, chosen.parent)),
                  "iterations": summary["iteration"], "env_steps": summary["env_steps"], "wall_s": summary["wall_s"],
                  "evaluation": preset["evaluation"], "screened": str(chosen.relative_to(out)),
                  "commands": [reproduce_line, "# which ran:", train_line]}
    from dataclasses import replace

    shipped = replace(spec, provenance=provenance)
    dump_spec(shipped, out / "learned.yaml", f"{spec.name}, reproduced by {reproduce_line}")
    print(f"[3/5] ship: {out / 'learned.yaml'}", flush=True)
    policy = build(load_spec(out / "learned.yaml"), out, source="learned.yaml")
    criteria = Criteria.quick() if preset["evaluation"] == "quick" else Criteria()
    print(f"[4/5] evaluate: the acceptance checks ({preset['evaluation']})", flush=True)
    evaluation = acceptance(policy, criteria)
    (out / "evaluation.json").write_text(strict_json.dumps(evaluation, indent=2) + "\n")
    (out / "MODEL_CARD.md").write_text(model_card(shipped, evaluation, provenance))
    print(f"[5/5] model card: {out / 'MODEL_CARD.md'}", flush=True)
    print(strict_json.dumps({"out": str(out), "spec": str(out / "learned.yaml"), "passed": evaluation["passed"],
                             "failures": evaluation["failures"]}))
    return 0
