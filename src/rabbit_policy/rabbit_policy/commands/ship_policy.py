"""Ship a trained HZD-RL policy as ``rabbit_policy``'s package data, with a model card.

    scripts/ship_policy.py runs/es0/best.pt [--compare runs/ppo0/best.pt ...] [--dry-run]
                           [--allow-failing] [--quick] [--workers 2]

Runs the learning issue's acceptance checks 1-6 (``rabbit_policy.evaluation.acceptance.
broad_acceptance``: every speed, every ordered change at every phase, 100 random command
sequences, push margins against classic HZD's and three scenarios beyond them, model
errors, Poincaré) on the policy and on classic HZD's best variant (the calibrated library,
every 20 ticks) for comparison, and the 9-speed tracking table (``acceptance``) on the
policy, each ``--compare`` file, the network the run started from (its warm start,
rebuilt: what training added) and the classic library. Then writes, in ``--out DIR`` (never into the package: its
learned controller is what ``reproduce.py --preset shipped`` writes): the checkpoint as ``hzd_rl_policy.pt``, ``MODEL_CARD.md`` and
``evaluation.json`` (every figure: algorithm, seed, workers, training time and steps from the
checkpoint's ``info``, the exact commands, the tables) and its spec ``learned.yaml`` with its
weights (``rabbit_policy.spec.convert.learned_spec``: the controller that walk.py, run_stack
and policy_node run, built as the checks ran it). Refuses a policy
that fails checks 1-6 unless ``--allow-failing`` (the card then lists what fails).
``--dry-run`` prints the card without writing anything; ``--quick`` runs the fast subset
(``RobustnessConfig.quick()`` and the policy's own tracking table, for a first look: never
ship on it).
"""

from __future__ import annotations

import argparse
import shlex
import shutil
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

from rabbit_msgs_py import strict_json
from rabbit_msgs_py.cli import ArgumentParser
from rabbit_policy.evaluation.acceptance import broad_table
from rabbit_policy.parallel import ProgressMap, add_backend_arguments, open_backend
from rabbit_policy.runtime.recovery import RecoveryConfig

FEEDFORWARD_SPEEDS = tuple(round(0.7 + 0.025 * i, 3) for i in range(33))
"""``--integral-feedforward``'s table speeds (m/s): the library's range, every 0.025."""
"""Where ``--ship`` writes: the package's ``rabbit_policy/trained`` (editable in a clone)."""


def fmt(value, digits: int = 3) -> str:
    return "—" if value is None else f"{value:.{digits}f}"


def evaluation_table(results: list[tuple[str, dict]], criteria) -> list[str]:
    """Markdown rows: per controller, the constant-speed errors and the schedule reach times
    (``criteria``: the :class:`~rabbit_policy.evaluation.acceptance.Criteria` they ran with)."""
    speeds = [c["speed"] for c in results[0][1]["constant"]]
    lines = [f"Constant speed, {criteria.constant_duration:g} s (mean hip speed over the last "
             f"{criteria.average_over:g} s minus the command, m/s; `fell` if it fell):", "",
             "| controller | " + " | ".join(f"{v:.1f}" for v in speeds) + " |",
             "|---|" + "---|" * len(speeds)]
    for name, result in results:
        cells = ["fell" if c["fell"] else f"{c['error']:+.3f}" for c in result["constant"]]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    schedule = results[0][1]["schedule"]["segments"]
    sequence = " → ".join(f"{s['command']:.1f}" for s in schedule)
    lines += ["", f"Speed schedule {sequence} m/s, {criteria.segment_duration:g} s each (seconds to the first "
              f"one-step average within {criteria.speed_tolerance:g} m/s; goal ≤ {criteria.reach_within:g} s):", "",
              "| controller | " + " | ".join(f"{s['command']:.1f}" for s in schedule) + " | fell | passed |",
              "|---|" + "---|" * (len(schedule) + 2)]
    for name, result in results:
        cells = [fmt(s["reach_time"], 2) for s in result["schedule"]["segments"]]
        lines.append(f"| {name} | " + " | ".join(cells) +
                     f" | {result['schedule']['fell']} | {'yes' if result['passed'] else 'no'} |")
    return lines


def train_command(info: dict, keep_evaluated: bool = False, iterations: int | None = None) -> str:
    """The ``scripts/train.py`` command line that reproduces a checkpoint (deterministic
    for the seed and worker count; ``best.pt`` also depends on ``--eval-every``);
    ``keep_evaluated``: it keeps every evaluated policy (a screened file is one of them);
    ``iterations``: how far to train (default: the checkpoint's iteration)."""
    algo = info.get("algorithm")
    parts = ["scripts/train.py", "--algo", str(algo), "--seed", str(info.get("seed")), "--workers",
             str(info.get("workers")), "--warm-start", str(info.get("warm_start")), "--iterations",
             str(iterations if iterations is not None else info.get("iteration"))]
    if info.get("eval_every") is not None:
        parts += ["--eval-every", str(info["eval_every"])]
    if keep_evaluated:
        parts.append("--keep-evaluated")
    from dataclasses import fields

    from rabbit_msgs_py.cli import config_flag
    from rabbit_policy.learning.es import ESConfig
    from rabbit_policy.learning.ppo import PPOConfig

    for field in fields({"es": ESConfig, "ppo": PPOConfig}.get(algo, ESConfig)):
        value = info.get("config", {}).get(field.name)
        if field.metadata.get("cli", True) and field.name != "seed" and value is not None:
            parts += [config_flag(field), str(value)]
    return " ".join(parts + ["--out", "runs/X"])


def screened_through(info: dict, screened: str) -> int:
    """The last iteration a screen command names (its ``evaluated/NNNNN.pt`` files, brace lists
    too), or the checkpoint's own: the run must train that far to write every file screened."""
    import re

    named = [int(n) for n in re.findall(r"(?<![0-9])([0-9]{5})(?![0-9])", screened)]
    return max([int(info.get("iteration", 0)), *named])


def distribution_text(name: str) -> str:
    """What an episode of the named training distribution draws (``learning.env.DISTRIBUTIONS``)."""
    from rabbit_policy.learning.env import DISTRIBUTIONS

    d = DISTRIBUTIONS[name]
    if d.command_interval is None:
        parts = ["v_d uniform in [0.7, 1.5] m/s, changed once"]
    else:
        parts = [f"a new command every {d.command_interval[0]:g}-{d.command_interval[1]:g} s"]
    if d.push_probability:
        parts.append(f"a push with probability {d.push_probability:g}, {d.min_impulse:g}-{d.max_impulse:g} N s "
                     "either way at a random time")
    if d.frictions != (None,):
        parts.append("friction from " + ", ".join("packaged" if f is None else f"{f:g}" for f in d.frictions))
    if d.torso_mass_scales != (1.0,):
        parts.append("torso mass × " + ", ".join(f"{m:g}" for m in d.torso_mass_scales))
    if d.variants != ("paper",):
        parts.append("model variants " + ", ".join(d.variants))
    if d.torque_delays != (0.0,):
        parts.append("torque delays " + ", ".join(f"{1000 * t:g}" for t in d.torque_delays) + " ms")
    if d.observation_noise:
        parts.append(f"speed noise σ {d.observation_noise:g} m/s")
    return f"the {name} distribution: " + "; ".join(parts)


def recorded_integral(info: dict):
    """The speed integral a checkpoint's ``info`` records (its ``memory``), parsed once:
    an :class:`~rabbit_policy.runtime.speed_integral.IntegralConfig`."""
    from rabbit_policy.runtime.memory import MemoryConfig

    return MemoryConfig.from_dict(info["memory"]).integral


def network_text(info: dict) -> list[str]:
    """The card's first paragraphs: the network's inputs, outputs and rates, from the
    checkpoint's ``info`` (what :class:`~rabbit_policy.runtime.policies.NetworkPolicy` runs)."""
    from rabbit_hzd_controller.controller import ControllerConfig
    from rabbit_policy.runtime.memory import INPUTS

    defaults = ControllerConfig()  # the blend a policy blend follows
    features, action = info.get("features", "paper"), info.get("action", "direct")
    cfg = info.get("config", {})
    period = cfg.get("decision_period")
    n_in = INPUTS.get(features, 3)
    output = info.get("output", "sigmoid")
    averaged = ("the mean hip speed v and the mean speed error v_d − v over the last step's duration (m/s; a "
                "moving average up to the decision)" if period else
                "the last step's mean hip speed v and mean speed error v_d − v (m/s; touchdown to touchdown)")
    inputs = [f"the commanded speed v_d (m/s), {averaged}"]
    if features in ("memory", "body"):
        integral = recorded_integral(info)
        decay, table = integral.windup_decay, integral.feedforward
        inputs.append(f"the integral of the speed error (m, clamped to ±{integral.limit:g}: anti-windup"
                      + (f"; held where v_d + {integral.gain:g} I would leave {integral.speed_range} m/s"
                         if integral.gain and integral.speed_range else "")
                      + (f"; held while |v_d − v| ≥ {integral.band:g} m/s, a transient" if integral.band else "")
                      + (f"; once the hip has passed a new v_d, within {decay.seconds:g} s of the change, what I "
                         f"wound up since the change decays with time constant {decay.tau:g} s until "
                         f"{decay.seconds:g} s after it"
                         + (" (a walk's start counts as a change up to v_d)" if decay.at_start else "")
                         + (f"; an error beyond {decay.disturbance:g} m/s at a constant v_d (a push) counts as a "
                            "change its way" if decay.disturbance else "")
                         if decay else "")
                      + ("; when v_d changes it moves by the difference of its steady values for the old and "
                         + ("the new v_d, and it starts a walk at its steady value for v_d" if table.start
                            else "the new v_d")
                         + f" (a feed-forward table of {len(table.speeds)} speeds measured on this network)"
                         if table else "")
                      + ")")
        inputs.append("the last action, normalised to [−1, 1] (21 numbers)")
    if features == "body":
        inputs.append("the body state at the decision: torso pitch (rad) and rate (rad/s), phase and its rate "
                      "(1/s), hip velocity (m/s)")
    if action == "residual":
        gain = info.get("integral_gain", 0.0)
        base = (f"the calibrated library's gait for v_d + {gain:g} I (classic HZD with Westervelt's event-based "
                f"speed integral, gain {gain:g} 1/s)" if gain else "the calibrated library's gait for v_d (classic HZD)")
        scale = info.get("residual_scale") or []
        bound = (f"±{scale[0]:g} rad on each coefficient, ±{scale[-1]:g} N m s/rad on Kd" if scale else "bounded")
        outputs = (f"a residual ({output} output, {bound}) added to {base}, the sum clipped to the direct bounds: "
                   "a zero output is that classic controller")
    else:
        outputs = f"the 20 free Bezier coefficients (rad) and Kd (N m s/rad), {output} output scaled to the action bounds"
    paper = "the paper's network" if n_in == 3 else f"the paper's network widened to {n_in} inputs"
    overlay = info.get("recovery_overlay")
    if overlay is not None:
        outputs += (f"; on top, the recovery controller's rule (`rabbit_policy.runtime.recovery.RecoveryOverlay`): "
                    "when the hip falls behind where it was at the same phase of the steps before (a step in "
                    f"which the rule's weight reached {RecoveryConfig().forget_weight:g} left out), its offsets "
                    "(rad, rows 1-4) are added in proportion to the deficit, held off while the hip's mean speed "
                    f"exceeds v_d by {overlay['fast_gate']:g} of it, and from a weight of {overlay['hold']:g} on "
                    "added to the network's last gait chosen before the rule acted"
                    + (f"; from {overlay['rise_until']:g} of phase to the touchdown its weight may fall, not rise"
                       if overlay.get("rise_until", 1.0) < 1.0 else ""))
    return [
        f"`hzd_rl_policy.pt`: {paper} ({n_in} → 12 → 12 → 12 → 21, tanh hidden layers, "
        f"{info.get('parameters', 633)} parameters; features `{features}`, action `{action}`). "
        "The training checkpoint; what runs is its spec (`learned.yaml` and its weights, which ship_policy writes), "
        "which `policy_node` (`policy:=learned`) and `scripts/walk.py --controller learned` load by default.", "",
        "- inputs, in order: " + "; ".join(inputs) + ".",
        f"- outputs: {outputs}.",
        "- rates: " + (f"a decision every {period} ticks (every {period} ms of sim time), the gait "
                       + (f"blended in by the policy itself (in alpha over {defaults.within_step_blend:g} of phase, "
                          f"queued for the touchdown from {defaults.within_step_until:g}, as the controller's defaults "
                          "would), the rule's offsets applied from the next tick; "
                          if (overlay or {}).get("policy_blend") else
                          "applied from the next tick (no blend, no queue); " if (overlay or {}).get("at_once")
                          else "blended in at once; ")
                       if period else "a decision once per step, for the next step; ")
        + "the PD controller tracks it at 1 kHz.",
        "- in the ROS stack: `policy_node` builds these inputs from `/cmd_speed`, `/hip_velocity` (1 kHz)"
        + (", `/hzd/step`, `/joint_states` and `/hzd/phase`" if features == "body" or overlay is not None
           else " and `/hzd/step`")
        + ", keeping the memory itself (`rabbit_policy.runtime.memory.SpeedMemory`, the loops' own code); "
        "it publishes `/hzd/alpha` and `/hzd/kd`.",
    ]


def card_header(info: dict, broad: list[tuple[str, dict]] | None = None) -> list[str]:
    """The model hubs' metadata header (YAML front matter, as Hugging Face's model cards
    carry it): licence, tags, the environment id the policy was trained on, and checks 1-6's
    verdicts as the model index's results (``broad``: the shipped policy's first)."""
    from rabbit_policy.learning.env import PRESETS, EpisodeConfig
    from rabbit_policy.registration import ENV_ID, PRESET_IDS

    fields = set(EpisodeConfig.__dataclass_fields__) - {"seed"}
    config = EpisodeConfig(**{k: v for k, v in info.get("config", {}).items() if k in fields})
    env_id = next((i for i, name in PRESET_IDS.items() if PRESETS[name] == config), ENV_ID)
    lines = ["---", "license: apache-2.0", "library_name: pytorch", "pipeline_tag: reinforcement-learning",
             "tags:", *(f"  - {t}" for t in ("reinforcement-learning", "robotics", "bipedal-locomotion",
                                              "hybrid-zero-dynamics", "mujoco", "ros2", info.get("algorithm", "es"),
                                              env_id)),
             "model-index:", "  - name: hzd_rl_policy", "    results:", "      - task:",
             "          type: reinforcement-learning", "          name: RABBIT walking with HZD",
             "        dataset:", f"          type: {env_id}", f"          name: {env_id}", "        metrics:"]
    if broad:
        checks = broad[0][1]["checks"]
        for name, check in checks.items():
            lines += [f"          - type: check_{name}", f"            value: {'pass' if check['passed'] else 'fail'}",
                      f"            name: acceptance check {name.replace('_', ' ', 1)}"]
        lines += ["          - type: acceptance_checks_passed",
                  f"            value: {sum(c['passed'] for c in checks.values())}/{len(checks)}",
                  "            name: checks 1-6 passed"]
    return lines + ["---", ""]


def overlay_flags(overlay: dict | None) -> str:
    """The ship_policy options that write a checkpoint's ``recovery_overlay`` record ('' for none)."""
    if overlay is None:
        return ""
    if overlay.get("policy_blend"):
        return " --recovery-overlay --recovery-overlay-policy-blend"
    return " --recovery-overlay --recovery-overlay-at-once" if overlay.get("at_once") else " --recovery-overlay"


def rules_set_after_training(info: dict) -> tuple[str, str]:
    """The ship_policy options that set the speed integral's rules the run trained without
    (``--integral-band``, ``--integral-windup-decay``, ``--integral-feedforward``), and the
    card's note saying so; empty strings if none."""
    config = info.get("config", {})
    integral = recorded_integral(info) if info.get("memory") else None
    band = None if config.get("integral_band") or integral is None else integral.band  # trained with it: not set after
    decay = None if config.get("integral_windup_decay") or integral is None else integral.windup_decay
    feedforward = integral.feedforward if integral is not None else None  # never trained with
    overlay = info.get("recovery_overlay")  # never trained with
    flags = (f" --integral-band {band:g}" if band else "") + (
        f" --integral-windup-decay {decay.seconds:g} --integral-windup-tau {decay.tau:g}"
        + (" --integral-windup-at-start" if decay.at_start else "") if decay else "") + (
        (" --integral-feedforward --integral-feedforward-start" if feedforward.start else " --integral-feedforward")
        if feedforward else "") + overlay_flags(overlay)
    names = " and ".join(["band"] * bool(band) + ["windup decay"] * bool(decay) + ["feed-forward"] * bool(feedforward))
    notes = ([f"the integral's {names}"] if names else []) + (
        ["the recovery rule on top (`RecoveryOverlay`)"] if overlay is not None else [])
    return flags, (f"; the run trained without {' or '.join(notes)}, which ship_policy sets on the shipped copy"
                   if notes else "")


def with_recovery_overlay(policy: Path, out: Path, at_once: bool = False, policy_blend: bool = False) -> Path:
    """A copy of the checkpoint ``policy`` at ``out`` that carries the recovery rule on top of
    its gait (``info["recovery_overlay"]``: :class:`~rabbit_policy.runtime.recovery.OverlayConfig`'s
    defaults, and ``at_once`` as given: the loops and the stack then apply its gaits at once;
    ``policy_blend``: at once, the overlay blending the network's own gaits in, and the rule's
    weight not rising from the phase where the controller's defaults queue a gait, 0.6).
    ``ValueError`` for a policy that does not decide within the step or already has the
    recovery controller under its residual."""
    from dataclasses import asdict

    from rabbit_hzd_controller.controller import ControllerConfig
    from rabbit_policy.runtime.network import PolicyCheckpoint
    from rabbit_policy.runtime.recovery import OverlayConfig

    checkpoint = PolicyCheckpoint.load(policy)
    info = checkpoint.info
    if not int(info.get("config", {}).get("decision_period", 0) or 0):
        raise ValueError(f"--recovery-overlay: {policy} decides once per step; the rule acts within the step")
    if info.get("residual_base", "classic") != "classic":
        raise ValueError(f"--recovery-overlay: {policy} is already a residual on {info['residual_base']!r}")
    rise_until = ControllerConfig().within_step_until if policy_blend else 1.0
    info["recovery_overlay"] = {**asdict(OverlayConfig(rise_until=rise_until)), "at_once": at_once or policy_blend,
                                "policy_blend": policy_blend}
    checkpoint.save(out)
    return out


def model_card(info: dict, results: list[tuple[str, dict]], broad: list[tuple[str, dict]] | None = None,
               command: str = "", criteria=None, screened: str = "") -> str:
    """The card's markdown; ``criteria``: the tracking checks' (default: the full ones);
    ``screened``: the screen command that chose this file among a run's evaluated policies
    (``train.py --keep-evaluated``; empty: the run's ``best.pt``)."""
    from rabbit_policy.evaluation.acceptance import Criteria

    criteria = criteria or Criteria()
    cfg = info.get("config", {})
    set_after, set_after_note = rules_set_after_training(info)
    if screened:
        selected = f"runs/X/evaluated/{int(info.get('iteration', 0)):05d}.pt"
        selection = (f" (this file is that run's `{selected.split('/', 2)[2]}`, chosen among every evaluated "
                     f"iteration by the held-out screen: `{screened}`)")
    else:
        selected = "runs/X/best.pt"
        selection = (" (this file is that run's `best.pt`: the evaluated iteration with the fewest failed "
                     "acceptance checks)")
    lines = [
        *card_header(info, broad),
        "# HZD-RL policy shipped with rabbit_policy", "",
        *network_text(info), "",
        "## Training", "",
        f"- algorithm: **{info.get('algorithm')}**, seed {info.get('seed')}, workers {info.get('workers')}, "
        f"warm start from the classic gait library: {info.get('warm_start')}",
        f"- iterations: {info.get('iteration')}, environment steps: {info.get('env_steps')}, "
        f"wall time: {info.get('wall_s')} s on the machine that trained it",
        f"- configuration: `{strict_json.dumps(cfg)}`",
        "- environment: `RabbitHZD-v0` (one env step = "
        + (f"{cfg['decision_period']} ticks" if cfg.get("decision_period") else "one walking step")
        + f"; reward −(v̄ − v_d)² per step, fall penalty {cfg.get('fall_penalty', -10.0):g}; episodes: "
        + distribution_text(cfg.get("distribution", "paper")) + ")",
        f"- regenerate: `{train_command(info, bool(screened), screened_through(info, screened))}`, then "
        f"`scripts/ship_policy.py {selected}"
        + set_after + (" --allow-failing" if broad and not broad[0][1]["passed"] else "") + f"`{selection}"
        + set_after_note,
        f"- shipped with: `{command}`" if command else "",
        "", "## Acceptance 1-6 (the learning issue; ROS-free fast path, "
        "`rabbit_policy.evaluation.acceptance.broad_acceptance`)", "",
        "Measured when it was shipped, on that machine's arithmetic; the committed report "
        "(`scripts/evaluate.py`, docs/results in the repository) measures the controller as it runs now.", "",
        *(broad_table(broad) if broad else ["not run"]), "",
        ("**Passes all six.**" if broad and broad[0][1]["passed"] else
         f"**Fails {', '.join(broad[0][1]['failed'])}**: shipped with `--allow-failing` as the best policy "
         "measured so far; see docs/evaluation.md for the numbers and what was tried.") if broad else "",
        "", "## Tracking checks (9 speeds and the speed schedule)", "",
        *evaluation_table(results, criteria), "",
    ]
    return "\n".join(lines)


def with_integral_rules(policy: Path, out: Path, band: float | None = None,
                        windup_decay: tuple[float, float] | tuple[float, float, bool] | None = None,
                        feedforward: tuple[float, ...] | None = None, feedforward_start: bool = False) -> Path:
    """A copy of the checkpoint ``policy`` at ``out`` whose speed integral is held while the
    speed error is ``band`` m/s or more (``IntegralConfig.band``) and whose windup after a
    command change decays, ``windup_decay`` = (seconds, tau) in s and optionally at_start
    (``IntegralConfig.windup_decay``);
    None: that rule as the checkpoint has it. ``feedforward``: also the integral's
    feed-forward table (``IntegralConfig.feedforward``) at these speeds (m/s), measured on the
    copy with those rules (:func:`~rabbit_policy.evaluation.steady_integral.steady_integrals`:
    a minute for its 33 speeds), acting at a walk's start too if ``feedforward_start``.
    ``ValueError`` naming the option for a policy without the memory inputs or a value that
    is not a number > 0."""
    from rabbit_policy.runtime.memory import MemoryConfig
    from rabbit_policy.runtime.network import PolicyCheckpoint
    from rabbit_policy.runtime.speed_integral import WindupDecay

    checkpoint = PolicyCheckpoint.load(policy)
    if "memory" not in checkpoint.info:
        option = ("--integral-band" if band is not None else "--integral-windup-decay" if windup_decay is not None
                  else "--integral-feedforward")
        raise ValueError(f"{option}: {policy} has no speed integral (features "
                         f"{checkpoint.info.get('features', 'paper')!r}; it needs memory or body)")
    memory = MemoryConfig.from_dict(checkpoint.info["memory"])
    for option, name, value in (("--integral-band", "band", band),
                                ("--integral-windup-decay", "windup_decay", windup_decay)):
        if value is not None:
            try:
                memory = memory.with_integral(**{name: WindupDecay(*value) if name == "windup_decay" else value})
            except ValueError as exc:
                raise ValueError(f"{option}: {exc}") from None
    checkpoint.info["memory"] = memory.to_dict()
    checkpoint.save(out)
    if feedforward is not None:
        from rabbit_policy.evaluation.steady_integral import steady_integrals
        from rabbit_policy.spec.make import checkpoint_policy

        try:
            table = steady_integrals(checkpoint_policy(out), feedforward)
            memory = memory.with_integral(feedforward=replace(table, start=feedforward_start))
        except ValueError as exc:
            raise ValueError(f"--integral-feedforward: {exc}") from None
        checkpoint.info["memory"] = memory.to_dict()
        checkpoint.save(out)
    return out


def write_spec(checkpoint_file: Path, directory: Path, command: str, ran_on: dict) -> None:
    """The shipped checkpoint's spec, ``directory/learned.yaml`` with its weights beside it
    (:func:`rabbit_policy.spec.convert.learned_spec`), its provenance the command that shipped it."""
    from rabbit_policy.runtime.network import PolicyCheckpoint
    from rabbit_policy.spec import dump_spec
    from rabbit_policy.spec.convert import learned_spec

    directory.mkdir(parents=True, exist_ok=True)
    spec = learned_spec(PolicyCheckpoint.load(checkpoint_file), directory, provenance={
        "written_by": command, "checkpoint": checkpoint_file.name, **ran_on})
    dump_spec(spec, directory / "learned.yaml", f"learned, shipped by {command}")


def warm_start_policy(checkpoint):
    """The network the run started from (its warm start, rebuilt from the checkpoint's
    seed and bounds; deterministic), or None if it started from random weights."""
    import torch

    from rabbit_msgs_py.decision_ticks import PER_STEP
    from rabbit_policy.runtime.gait_library import GaitLibrary
    from rabbit_policy.runtime.network import PolicyCheckpoint
    from rabbit_policy.spec.make import policy_of_checkpoint
    from rabbit_policy.learning.warm_start import WARM_STARTS, initial_network

    name = checkpoint.info.get("warm_start")
    if name not in WARM_STARTS:
        return None
    torch.set_num_threads(1)  # as scripts/train.py
    net, _ = initial_network(checkpoint.low, checkpoint.high, GaitLibrary.load(),
                             int(checkpoint.info.get("seed", 0)), name)
    return policy_of_checkpoint(PolicyCheckpoint(net.state_dict(), checkpoint.low, checkpoint.high, {}),
                                f"warm start ({name})", PER_STEP)


def main(argv: list[str] | None = None) -> int:
    from rabbit_policy.experiment.options import add_allow_dirty_option, add_classic_integral_option

    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("policy", type=Path)
    parser.add_argument("--compare", type=Path, nargs="*", default=[], help="more policy files for the table")
    parser.add_argument("--allow-failing", action="store_true")
    parser.add_argument("--dry-run", action="store_true")
    parser.add_argument("--quick", action="store_true", help="the fast subset of checks 1-6 (a first look)")
    add_allow_dirty_option(parser)
    add_classic_integral_option(parser)
    parser.add_argument("--integral-band", type=float, metavar="B",
                        help="ship the policy with its speed integral held while |v_d - v| >= B m/s (conditional "
                             "integration, rabbit_policy.runtime.speed_integral; a memory policy only): the shipped "
                             "copy records it, and every check runs on it")
    parser.add_argument("--integral-windup-decay", type=float, metavar="SECONDS",
                        help="ship the policy with what its speed integral winds up after a command change decaying "
                             "once the hip has passed the new command, within and until SECONDS s after the change "
                             "(rabbit_policy.runtime.speed_integral.WindupDecay; a memory policy only): the shipped "
                             "copy records it, and every check runs on it")
    parser.add_argument("--integral-windup-tau", type=float, default=1.0, metavar="TAU",
                        help="--integral-windup-decay's time constant (s; default 1)")
    parser.add_argument("--integral-windup-at-start", action="store_true",
                        help="with --integral-windup-decay: a walk's start counts as a change of the command up "
                             "to v_d, so what the integral winds up over the first (slow) steps decays too "
                             "(WindupDecay.at_start)")
    parser.add_argument("--integral-feedforward", action="store_true",
                        help="ship the policy with its speed integral moving by the difference of its steady values "
                             "when the command changes (a table measured on the policy with its other rules, "
                             "rabbit_policy.runtime.speed_integral.IntegralFeedforward; a memory policy only): the "
                             "shipped copy records it, and every check runs on it")
    parser.add_argument("--integral-feedforward-start", action="store_true",
                        help="with --integral-feedforward: the integral also starts a walk at its steady value for "
                             "the command (off by default: see IntegralFeedforward)")
    parser.add_argument("--recovery-overlay", action="store_true",
                        help="ship the policy with the recovery controller's rule on top of its gait (rabbit_policy."
                             "runtime.recovery.RecoveryOverlay: a backward push's deficit adds the rule's offsets, "
                             "blended in as the network's gait): the shipped copy records it, and every check runs "
                             "on it")
    parser.add_argument("--recovery-overlay-at-once", action="store_true",
                        help="with --recovery-overlay: the controller applies every gait at once (no blend, no queue: "
                             "the recovery controller's settings) instead of as the network was trained")
    parser.add_argument("--recovery-overlay-policy-blend", action="store_true",
                        help="with --recovery-overlay: the controller applies every gait at once and the overlay "
                             "blends the network's own gaits in itself, as the controller's defaults would (rabbit_policy."
                             "runtime.alpha_blend.AlphaBlend), so only the rule's offsets act at once "
                             "(the spec's blend section)")
    parser.add_argument("--out", type=Path, default=None, metavar="DIR",
                        help="write the checkpoint, card, evaluation and spec here (needed unless --dry-run: the "
                             "package's learned controller is what scripts/reproduce.py --preset shipped writes)")
    parser.add_argument("--screened", default="", metavar="COMMAND",
                        help="the scripts/screen_policies.py command that chose POLICY among a run's evaluated "
                             "policies (train.py --keep-evaluated), for the card")
    add_backend_arguments(parser, progress=True)
    args = parser.parse_args(argv)
    if args.out is None and not args.dry_run:
        parser.error("--out DIR is needed (or --dry-run): the package's learned controller is what "
                     "scripts/reproduce.py --preset shipped writes")
    ran_on: dict = {}
    if not args.dry_run:  # before the measurements: a refused tree costs nothing
        from rabbit_policy.spec.provenance import DirtyTree, shipping_provenance

        try:
            ran_on = shipping_provenance(args.allow_dirty)
        except DirtyTree as exc:
            parser.error(str(exc))
    args.provenance = ran_on
    if args.integral_feedforward_start and not args.integral_feedforward:
        parser.error("--integral-feedforward-start needs --integral-feedforward")
    if args.integral_windup_at_start and args.integral_windup_decay is None:
        parser.error("--integral-windup-at-start needs --integral-windup-decay")
    if (args.recovery_overlay_at_once or args.recovery_overlay_policy_blend) and not args.recovery_overlay:
        parser.error("--recovery-overlay-at-once and --recovery-overlay-policy-blend need --recovery-overlay")
    if args.recovery_overlay_at_once and args.recovery_overlay_policy_blend:
        parser.error("--recovery-overlay-at-once and --recovery-overlay-policy-blend: choose one")
    with tempfile.TemporaryDirectory(prefix="rabbit_ship_") as scratch:  # the copy with --integral-* rules
        return ship(parser, args, argv, Path(scratch))


def ship(parser, args, argv: list[str] | None, scratch: Path) -> int:
    """Measure, write the card and ship (``main``'s work once its arguments are parsed);
    ``scratch``: a directory for the policy's copies with its ``--integral-*`` and ``--recovery-overlay`` rules."""
    from rabbit_policy.evaluation.acceptance import Criteria, acceptance, broad_comparison
    from rabbit_policy.runtime.policies import PolicyUnavailable
    from rabbit_policy.spec.make import make_policy

    source = args.policy
    try:
        decay = None if args.integral_windup_decay is None else (args.integral_windup_decay, args.integral_windup_tau,
                                                                 args.integral_windup_at_start)
        if args.recovery_overlay:  # (the feed-forward table is the network's own: measured without the overlay)
            source = with_recovery_overlay(source, scratch / f"overlay_{args.policy.name}",
                                           args.recovery_overlay_at_once, args.recovery_overlay_policy_blend)
        if args.integral_band is not None or decay is not None or args.integral_feedforward:
            source = with_integral_rules(source, scratch / args.policy.name, args.integral_band, decay,
                                         FEEDFORWARD_SPEEDS if args.integral_feedforward else None,
                                         args.integral_feedforward_start)
        policy = make_policy("learned", policy_file=source)
        others = [make_policy("learned", policy_file=p) for p in args.compare]
    except (PolicyUnavailable, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    info = policy.checkpoint.info
    criteria = Criteria.quick() if args.quick else Criteria()

    def log(message: str) -> None:
        print(message, file=sys.stderr, flush=True)

    backend = open_backend(parser, args)
    map_fn = ProgressMap(backend, "acceptance walks", enabled=not args.no_progress)
    try:
        integral = [(f"classic HZD + speed integral {ki:g}", make_policy("classic", speed_integral=ki))
                    for ki in args.classic_integral]
        measured = dict(broad_comparison([("learned", policy), *integral], args.quick, map_fn, log))
        broad = [(f"HZD-RL ({info.get('algorithm')})", measured["learned"]),
                 ("classic HZD (calibrated library, every 20 ticks)", measured["classic"]),
                 *[(name, measured[name]) for name, _ in integral]]
        log("tracking checks")
        results = [(f"HZD-RL ({info.get('algorithm')}, shipped)", acceptance(policy, criteria, map_fn=map_fn))]
        if not args.quick:  # the fast subset: the policy's own tracking table only
            for other in others:
                other_info = other.checkpoint.info
                results.append((f"HZD-RL ({other_info.get('algorithm')}, iteration {other_info.get('iteration')})",
                                acceptance(other, criteria, map_fn=map_fn)))
            start = warm_start_policy(policy.checkpoint)
            if start is not None:
                results.append((f"warm start only ({info.get('warm_start')}, untrained)",
                                acceptance(start, criteria, map_fn=map_fn)))
            for mode in ("nearest", "interpolate"):
                results.append((f"classic HZD ({mode})", acceptance(make_policy("classic", mode=mode), criteria,
                                                                    map_fn=map_fn)))
            for name, controller in integral:
                results.append((name, acceptance(controller, criteria, map_fn=map_fn)))
    finally:
        map_fn.close()
        backend.close()
    command = shlex.join(["scripts/ship_policy.py", *(argv if argv is not None else sys.argv[1:])])
    card = model_card(info, results, broad, command, criteria, args.screened)
    print(card)
    if not broad[0][1]["passed"] and not args.allow_failing:
        print(f"error: the policy fails acceptance checks {', '.join(broad[0][1]['failed'])}; not shipped "
              "(--allow-failing to ship it anyway, the card saying so)", file=sys.stderr)
        return 1
    if not args.dry_run:
        record = spec_dir = args.out
        record.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(source, record / "hzd_rl_policy.pt")
        (record / "MODEL_CARD.md").write_text(card)
        (record / "evaluation.json").write_text(strict_json.dumps({"acceptance_1_6": dict(broad),
                                                                    "tracking": dict(results)}, indent=1) + "\n")
        write_spec(source, spec_dir, command, args.provenance)
        print(f"shipped to {record / 'hzd_rl_policy.pt'} and {spec_dir / 'learned.yaml'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
