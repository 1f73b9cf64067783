"""Reproduce the paper's section IV for classic HZD, HZD-RL and the model-based recovery
controller, with figures and a report.

    scripts/evaluate.py [--out DIR] [--quick] [--workers 2] [--policy-file P] [--no-video] [--ablation JSON ...]

Runs on the ROS-free fast path (the nodes' model and controller, no ROS):

* speed tracking through a schedule of commanded speeds (filtered speed, mean error and
  settling time per segment);
* limit cycles: phase portraits at several speeds after a perturbation, and the
  Poincaré test (eigenvalues of the step-to-step return map's Jacobian);
* push recovery: three push scenarios at 2, 4 and 6 s, who fell, speed plots, each
  scenario as a rate over its neighbourhood (the pushes shifted together, speeds around
  1.0 m/s; Wilson intervals, McNemar's test against learned), an impulse sweep, repeated
  pushes (three equal pushes 2 s apart, broadly) and a GIF of each controller under the pushes;

with ``--ablation``, the checks 1-6 table of ``scripts/compare_policies.py --out`` files (the
learning issue's ablation); and writes ``DIR/report.md``, ``DIR/results.json`` (every number behind the figures,
and the provenance: the code's commit and the machine), ``DIR/headline.md`` (README's results table) and
the PNG/GIF files. ``--quick`` is a short version for tests. The
committed report in ``docs/results/`` was made with ``scripts/evaluate.py --out docs/results``.
Exit status: 0 written, 2 bad arguments or no policy.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from rabbit_msgs_py import strict_json
from rabbit_msgs_py.cli import ArgumentParser, ensure_output_dir
from rabbit_msgs_py.environment import ensure_localhost_discovery
from rabbit_policy.parallel import ProgressMap, add_backend_arguments, open_backend
from rabbit_msgs_py.gl_backend import choose_headless_gl

# MuJoCo picks its OpenGL backend when it is first imported: headless EGL (or OSMesa)
# unless the user chose one
choose_headless_gl()


def build_parser() -> argparse.ArgumentParser:
    from rabbit_policy.experiment.options import add_gait_dir_option, add_model_option, add_policy_file_option

    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("evaluation"), help="output directory (created; files replaced)")
    parser.add_argument("--quick", action="store_true", help="short version for tests")
    add_backend_arguments(parser, progress=True)
    add_model_option(parser)
    add_gait_dir_option(parser)
    add_policy_file_option(parser)
    parser.add_argument("--no-video", action="store_true", help="skip the GIFs")
    parser.add_argument("--ablation", nargs="+", default=[], metavar="JSON",
                        help="scripts/compare_policies.py --out files: their checks 1-6 table joins the report")
    return parser


def render_videos(walks: dict, scenarios: tuple[str, ...], out: Path, config, model) -> list[dict]:
    """One GIF per controller and push scenario, from the recorded walks; a rendering
    failure is reported in the entry, not raised."""
    from rabbit_sim.physics.model import load_model
    from rabbit_sim.rendering import RenderingUnavailable, caption_frames, frame_indices, render_frames, save_gif

    model = load_model(model)
    width, height = config.video_size
    videos = []
    for scenario in scenarios:
        for name, by_scenario in walks.items():
            walk = by_scenario[scenario]
            entry = {"controller": name, "scenario": scenario}
            try:
                shown = frame_indices(walk.times, config.video_fps)
                frames = caption_frames(render_frames(model, walk.qpos[shown], width, height), walk.times[shown],
                                        walk.scenario.pushes)
                file = f"{name}_{scenario}.gif"
                save_gif(frames, out / file, config.video_fps, hold_last=1.5 if walk.failed else 0.0)
                videos.append({**entry, "file": file, "frames": len(frames), "failed": walk.failed})
            except RenderingUnavailable as exc:
                videos.append({**entry, "error": str(exc)})
    return videos


def judge_policy(policy, robust: dict, classic_margins: list[dict], stability: dict, map_fn) -> dict:
    """Checks 1-6 for one controller from this evaluation's results, plus the paper's push
    scenarios beyond classic's margins (three walks)."""
    from rabbit_policy.evaluation.acceptance import _scenario_job, judge, beyond_classic_scenarios, policy_outputs

    speeds = sorted({m["speed"] for m in classic_margins})
    speed = 1.0 if 1.0 in speeds else speeds[0]
    scenarios = list(map_fn(_scenario_job, [(policy, speed, s) for s in beyond_classic_scenarios(classic_margins, speed)]))
    return judge(robust, classic_margins, [{k: s[k] for k in ("name", "impulse_Ns", "survived")} for s in scenarios],
                 stability, max(s["peak_torque"] for s in scenarios), policy_outputs(policy))


def main(argv: list[str] | None = None) -> int:
    os.environ.setdefault("PYTHONUNBUFFERED", "1")  # worker processes print as they go
    ensure_localhost_discovery()
    parser = build_parser()
    args = parser.parse_args(argv)
    ensure_output_dir(parser, args.out)  # before any work: one line, exit 2

    from rabbit_policy.evaluation import section_iv as evaluation
    from rabbit_policy.evaluation import figures
    from rabbit_policy.evaluation.report import headline_table, load_comparisons, render_ablation, render_report
    from rabbit_policy.evaluation.robustness import robustness
    from rabbit_policy.spec.provenance import provenance
    from rabbit_policy.evaluation.steady_integral import network_alone
    from rabbit_policy.runtime.policies import CONTROLLERS, NetworkPolicy, PolicyUnavailable
    from rabbit_policy.spec.make import make_policy
    from rabbit_sim.physics.model import ModelOptions

    try:
        learned = make_policy("learned", policy_file=args.policy_file)
        is_network = isinstance(learned, NetworkPolicy)
        gain = learned.spec.speed_integral.gain if is_network and learned.spec.speed_integral else 0.0
        policies = {"classic": make_policy("classic", args.gait_dir),  # the order of the report's columns
                    # what the learning adds: classic with the learned spec's integral gain, the network alone
                    "classic_integral": make_policy("classic", args.gait_dir, speed_integral=gain) if gain else None,
                    "recovery": make_policy("recovery", args.gait_dir),
                    "network_alone": network_alone(learned) if is_network else None,
                    "learned": learned}
        policies = {name: policy for name, policy in policies.items() if policy is not None}
        ablation = load_comparisons(args.ablation)
    except (PolicyUnavailable, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    model = ModelOptions(args.model)
    config = evaluation.EvaluationConfig.quick() if args.quick else evaluation.EvaluationConfig()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    ran_on = provenance()  # the code and the machine, as the run starts
    log = lambda message: print(f"[{time.perf_counter() - start:6.1f} s] {message}", file=sys.stderr)  # noqa: E731

    backend = open_backend(build_parser(), args)
    map_fn = ProgressMap(backend, "evaluation walks", enabled=not args.no_progress)
    try:
        log("speed tracking")
        tracking = {name: evaluation.speed_tracking(policy, config, model)[0] for name, policy in policies.items()}
        figures.tracking_figure(tracking, out / "tracking.png")

        log("limit cycles")
        cycles: dict = {}
        for name, policy in policies.items():
            walks = {}
            cycles[name] = {}
            for speed in config.portrait_speeds:
                cycles[name][f"{speed:.2f}"], walks[speed] = evaluation.limit_cycle(policy, speed, config, model)
            figures.limit_cycle_figure(walks, figures.LABELS[name], out / f"limit_cycle_{name}.png")
        figures.convergence_figure(cycles, out / "convergence.png")

        log("Poincaré test")
        # which decisions read the measured state (all but classic's: the integral, the rule, the network)
        poincare = evaluation.poincare({n: (p, n != "classic") for n, p in policies.items()}, config, model, map_fn)
        figures.poincare_figure(poincare, out / "poincare.png")

        log("push scenarios")
        push, push_walks = evaluation.push_experiment(policies, config, model)
        figures.push_figure(push, out / "push.png")
        if config.neighbourhood is not None:
            log("push scenarios over their neighbourhoods")
            push["neighbourhood"] = evaluation.scenario_rates(policies, config, model, map_fn)
        sweep = {}
        if config.sweep is not None:
            log("impulse sweep")
            sweep = evaluation.push_sweep(policies, config, model, map_fn)
            figures.sweep_figure(sweep, out / "sweep.png")
        repeated = {}
        if config.repeated is not None:
            log("repeated pushes")
            repeated = evaluation.repeated_push_table(policies, config, model, map_fn)
        robust = {}
        if config.robustness is not None:
            for name, policy in policies.items():
                robust[name] = robustness(policy, config.robustness, map_fn, log)
            figures.transitions_figure(robust, out / "transitions.png")
            figures.margins_figure(robust, out / "margins.png")
            figures.survival_figure(robust, out / "survival.png")
            figures.model_cases_figure(robust, out / "model_cases.png")
            log("acceptance checks 1-6")
            verdicts = {name: judge_policy(policy, robust[name], robust["classic"]["push_margins"],
                                           poincare[name], map_fn) for name, policy in policies.items()}
    finally:
        map_fn.close()
        backend.close()

    videos: list[dict] = []
    if not args.no_video:
        log("videos")
        videos = render_videos({n: w for n, w in push_walks.items() if n in CONTROLLERS}, config.video_scenarios, out,
                               config, model)

    command = ("scripts/evaluate.py" + (" --quick" if args.quick else "") + f" --out {args.out}"
               + (" --ablation " + " ".join(args.ablation) if args.ablation else ""))
    results = {"meta": {"command": command, "model": model.to_dict(), "workers": args.workers,
                        "wall_time_s": time.perf_counter() - start, "provenance": ran_on,
                        "controllers": {n: p.name for n, p in policies.items()}},
               "config": config.to_dict(), "tracking": tracking, "limit_cycle": cycles, "poincare": poincare,
               "push": push, "push_sweep": sweep, "repeated_pushes": repeated, "robustness": robust,
               "acceptance_1_6": verdicts if config.robustness is not None else {}, "videos": videos,
               "ablation": ablation}
    (out / "results.json").write_text(strict_json.dumps(results, indent=1))
    (out / "report.md").write_text(render_report(results))
    (out / "headline.md").write_text("\n".join(headline_table(results)) + "\n")  # README's and results.md's table
    if ablation:
        (out / "ablation.md").write_text(render_ablation(results))
    log(f"wrote {out / 'report.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
