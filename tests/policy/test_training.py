"""HZD-RL training and evaluation: the policy-in-the-loop walk, the acceptance checks, the
trainers (ES, PPO) through ``scripts/train.py``, and the shipped policy."""

from __future__ import annotations

import csv
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from rabbit_policy.learning.env import RabbitHZDEnv
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.memory import INPUTS
from rabbit_policy.runtime.network import PolicyCheckpoint, parameter_count
from rabbit_policy.runtime.policies import LibraryPolicy

from checkpoints import SHIPPED_BEFORE
from rabbit_policy.spec.make import checkpoint_policy, make_policy
from rabbit_policy.experiment.loop import walk, walk_gait
from rabbit_policy.experiment.result import Touchdown, WalkResult
from rabbit_policy.experiment.scenario import Push, Scenario

pytestmark = pytest.mark.sim

ROOT = Path(__file__).resolve().parents[2]
NEWER_FIELDS = {"features": "paper", "action": "direct", "integral_gain": 0.0, "alive_bonus": 0.0,
                "slow_penalty": 0.0, "roll_back_after": 0.0, "residual_base": "classic", "top": 0,
                "integral_band": 0.0, "integral_clip": 0.0, "integral_windup_decay": 0.0, "spec": "",
                "optimizer": "adam", "reward": "tracking", "guard": 0, "guard_slack": 0,
                "guard_set": "changes"}
"""ES options newer than a checkpoint, at the defaults that keep its run as it was."""
LIBRARY = GaitLibrary.load()


def run_script(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=timeout, cwd=ROOT)


# ------------------------------------------------------------------ policy in the loop
def test_walk_with_a_library_policy_matches_the_plain_gait_walk():
    gait = LIBRARY.nearest(1.1)
    result = walk(LibraryPolicy(LIBRARY, "nearest"), Scenario.constant(gait.speed), 10.0)
    plain = walk_gait(gait, 10.0)
    assert not result.failed and result.rejected == 0
    assert result.steps == plain.steps == len(result.decisions)
    assert result.mean_speed(5.0) == pytest.approx(plain.mean_speed(5.0), abs=0.01)
    # the policy's one-step averages are the steps' mean speeds (one definition), on the gait's speed
    step_means = [speed for _, _, speed in result.step_speeds()]
    assert [d.mean_speed for d in result.decisions] == pytest.approx(step_means, abs=1e-9)
    assert np.mean(step_means[-5:]) == pytest.approx(gait.speed, abs=0.06)


def test_speed_schedule_and_a_fatal_push_are_applied():
    policy = LibraryPolicy(LIBRARY, "nearest")
    result = walk(policy, Scenario(schedule=((0.0, 0.8), (4.0, 1.2))), 8.0)
    assert set(np.unique(result.desired_speed)) == {0.8, 1.2}
    assert result.desired_speed[result.times < 4.0 - 1e-6].max() == 0.8
    assert {d.desired_speed for d in result.decisions} == {0.8, 1.2}
    pushed = walk(policy, Scenario.constant(1.0, pushes=(Push(2.0, -400.0, 0.2),)), 6.0)
    assert pushed.fell and 2.0 < pushed.fall_time < 6.0
    with pytest.raises(ValueError, match="start at t = 0"):
        Scenario(schedule=((1.0, 1.0),))


def test_reach_times_take_the_first_step_inside_the_tolerance_after_the_change():
    # steps of 0.5 s with the given mean speeds: hip x at each touchdown
    speeds = [0.79, 0.81, 0.9, 1.0, 1.16, 1.21, 1.2]
    x, touchdowns = 0.0, []
    for k, v in enumerate(speeds, start=1):
        x += 0.5 * v
        touchdowns.append(Touchdown(0.5 * k, 0.0, x))
    result = WalkResult(Scenario(schedule=((0.0, 0.8), (1.2, 1.2))), False, None, False, None, 0.0, 0.0,
                        np.array([3.5]), np.array([x]), touchdowns)
    # the step ending at 1.5 s started at 1.0 s, before the change at 1.2 s: not counted
    assert [s["reach_time"] for s in result.segments()] == [pytest.approx(0.5), pytest.approx(1.3)]
    assert result.reach_time(1.2, 3.5, 1.5) is None


def test_env_reset_options_fix_the_two_commands():
    env = RabbitHZDEnv(max_steps=4)
    obs, info = env.reset(seed=3, options={"desired_speed": 0.8, "next_speed": 1.4})
    assert info["desired_speed"] == obs[0] == pytest.approx(0.8)
    seen = []
    for _ in range(4):
        obs, _r, _te, _tr, info = env.step(np.zeros(21, np.float32))
        seen.append(float(obs[0]))
    assert seen[-1] == pytest.approx(1.4) and seen[0] == pytest.approx(0.8)
    with pytest.raises(ValueError, match="outside"):
        env.reset(options={"desired_speed": 2.0})


# ------------------------------------------------------------------------- trainers
def read_csv(path: Path) -> list[dict]:
    with path.open() as f:
        return list(csv.DictReader(f))


def tensorboard_scalars(directory: Path) -> dict[str, list]:
    """Every scalar series in a TensorBoard log directory, read with TensorBoard's own reader."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(directory))
    events.Reload()
    return {tag: events.Scalars(tag) for tag in events.Tags()["scalars"]}


@pytest.mark.slow
def test_train_es_logs_checkpoints_and_resumes_exactly(tmp_path):
    common = ["scripts/train.py", "--algo", "es", "--seed", "3", "--workers", "2", "--pairs", "2",
              "--episodes", "2", "--max-steps", "4", "--no-progress", "--checkpoint-every", "1",
              "--warm-start", "none", "--decision-period", "0", "--distribution", "paper"]
    # the warm start has tests of its own (test_env); here it only costs time
    straight = run_script(*common, "--out", str(tmp_path / "a"), "--iterations", "2", "--eval-every", "2",
                          "--keep-evaluated")
    assert straight.returncode == 0, straight.stderr
    log = read_csv(tmp_path / "a" / "log.csv")
    assert [int(r["iteration"]) for r in log] == [1, 2]
    for key in ("episode_return", "mean_abs_error", "fall_fraction", "env_steps", "wall_s"):
        assert key in log[0]
    evals = read_csv(tmp_path / "a" / "eval.csv")
    assert [int(r["iteration"]) for r in evals] == [0, 2]  # the starting network, then every 2
    # the starting network's acceptance row: failures counted over the 9 speeds + 5 segments + the fall
    assert 0 <= int(evals[0]["failures"]) <= 15 and evals[0]["passed"] in ("True", "False")
    best = PolicyCheckpoint.load(tmp_path / "a" / "best.pt").info  # the starting network is only a baseline
    assert best["iteration"] == 2 and best["acceptance"]["failures"] == int(evals[1]["failures"])
    kept = sorted(p.name for p in (tmp_path / "a" / "evaluated").iterdir())  # --keep-evaluated: each one
    assert kept == ["00000.pt", "00002.pt"]
    assert [PolicyCheckpoint.load(tmp_path / "a" / "evaluated" / name).info["acceptance"]["failures"]
            for name in kept] == [int(r["failures"]) for r in evals]
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert summary["info"]["algorithm"] == "es" and summary["info"]["parameters"] == 633
    scalars = tensorboard_scalars(tmp_path / "a" / "tb")  # the same numbers, against env steps
    assert [s.step for s in scalars["rollout/episode_return"]] == [int(r["env_steps"]) for r in log]
    assert [s.value for s in scalars["rollout/episode_return"]] == pytest.approx(
        [float(r["episode_return"]) for r in log], rel=1e-6)
    assert [s.value for s in scalars["eval/failed_checks"]] == [float(r["failures"]) for r in evals]
    assert "es/population_mean" in scalars and "time/wall_s" in scalars
    plotted = run_script("scripts/plot_training.py", str(tmp_path / "a"), "--out", str(tmp_path / "curves.png"))
    assert plotted.returncode == 0 and (tmp_path / "curves.png").stat().st_size > 10_000, plotted.stderr
    assert run_script("scripts/plot_training.py", str(tmp_path / "nothing")).returncode == 2

    first = run_script(*common, "--out", str(tmp_path / "b"), "--iterations", "1", "--eval-every", "0")
    assert first.returncode == 0, first.stderr
    again = run_script(*common, "--out", str(tmp_path / "b"), "--iterations", "2", "--eval-every", "0")
    assert again.returncode == 2 and "not empty" in again.stderr
    resumed = run_script(*common, "--out", str(tmp_path / "b"), "--iterations", "2", "--eval-every", "0",
                         "--resume", "--backend", "ray")  # started on local, resumed on Ray
    assert resumed.returncode == 0, resumed.stderr
    a = PolicyCheckpoint.load(tmp_path / "a" / "policy.pt").state_dict
    b = PolicyCheckpoint.load(tmp_path / "b" / "policy.pt").state_dict
    assert all(torch.equal(a[k], b[k]) for k in a)  # 1 + resumed 1 == 2 straight
    logs = [read_csv(tmp_path / name / "log.csv") for name in ("a", "b")]
    drop_wall = [[{k: v for k, v in row.items() if k != "wall_s"} for row in log] for log in logs]
    assert drop_wall[0] == drop_wall[1]  # the same log, line for line
    assert make_policy("learned", policy_file=tmp_path / "b" / "policy.pt").name == "learned/policy.pt"


@pytest.mark.slow
def test_train_ppo_logs_its_losses_and_refuses_a_foreign_resume(tmp_path):
    """PPO through the script (its environments in forked processes; on Ray actors the same
    iteration is tested in test_parallel, and train.py --backend ray by the ES resume)."""
    result = run_script("scripts/train.py", "--algo", "ppo", "--seed", "1", "--workers", "1", "--envs", "2",
                        "--steps", "6", "--epochs", "2", "--minibatches", "2", "--max-steps", "5", "--eval-every", "0",
                        "--no-progress", "--iterations", "2", "--warm-start", "none", "--decision-period", "0",
                        "--distribution", "paper", "--out", str(tmp_path / "a"))
    assert result.returncode == 0, result.stderr
    log = read_csv(tmp_path / "a" / "log.csv")
    assert [int(r["iteration"]) for r in log] == [1, 2] and int(log[-1]["env_steps"]) == 24
    for key in ("policy_loss", "value_loss", "clip_fraction", "mean_abs_error"):
        assert np.isfinite(float(log[-1][key]))
    a = PolicyCheckpoint.load(tmp_path / "a" / "policy.pt")
    assert a.info["algorithm"] == "ppo"
    wrong = run_script("scripts/train.py", "--algo", "es", "--out", str(tmp_path / "a"), "--resume")
    assert wrong.returncode == 2 and "is an ppo run" in wrong.stderr


# ------------------------------------------------------------------- shipped policy
def test_the_learned_controller_shipped_is_what_reproduce_wrote_with_its_card_and_evaluation():
    """The packaged learned spec is ``reproduce.py --preset shipped``'s output: its provenance
    names the preset, a clean commit, every seed's run and the verdict; its card (beside it in
    ``trained/``) is that run's, its acceptance rows the stored evaluation's; the screen's
    evidence (docs/learning/zero_start_seeds/screen.json) names what shipped."""
    from rabbit_policy.spec import load_spec, packaged_spec

    spec = load_spec(packaged_spec("learned"))
    provenance = spec.provenance
    assert provenance["preset"].endswith("config/reproduce/shipped.yaml") and len(provenance["code_commit"]) == 40
    assert [r["seed"] for r in provenance["runs"]] == [0, 1, 2] and provenance["commands"][0].startswith(
        "scripts/reproduce.py --preset shipped ")
    trained = packaged_spec("learned").parent.parent / "trained"
    card = (trained / "MODEL_CARD.md").read_text()
    evaluation = json.loads((trained / "evaluation.json").read_text())
    for c in evaluation["acceptance"]["constant"]:
        assert f"| {c['speed']:.2f} | {c['mean_speed_last']:.3f} | {c['error']:+.3f} |" in card
    assert f"weights `{spec.network.weights.file}`" in card and provenance["commands"][0] in card
    screen = json.loads((ROOT / "docs" / "learning" / "zero_start_seeds" / "screen.json").read_text())
    assert screen["shipped"] == provenance["shipped"] and screen["beats_start"] == provenance["verdict"]["ships"]
    shipped_row = next(r for r in screen["candidates"] if r["candidate"] == screen["shipped"])
    assert evaluation["rates"] == shipped_row["rates"]


def test_the_checkpoint_shipped_before_has_its_model_card():
    path = SHIPPED_BEFORE
    assert path.is_file()
    assert (path.parent / "MODEL_CARD.md").is_file()
    policy = checkpoint_policy(path)
    info = policy.checkpoint.info
    assert info["algorithm"] in ("es", "ppo") and info["parameters"] == parameter_count(policy.checkpoint.network())
    card = (path.parent / "MODEL_CARD.md").read_text()
    inputs = INPUTS[info.get("features", "paper")]  # the card states the network the file holds
    assert f"({inputs} → 12 → 12 → 12 → 21, tanh hidden layers, {info['parameters']} parameters; " in card
    assert f"features `{info.get('features', 'paper')}`, action `{info.get('action', 'direct')}`" in card
    assert "- inputs, in order: " in card and "- outputs: " in card and "- rates: " in card


def _shipped_tracking() -> dict:
    stored = json.loads((SHIPPED_BEFORE.parent / "evaluation.json").read_text())["tracking"]
    return stored[next(k for k in stored if "shipped" in k)]


def test_the_model_card_states_the_stored_evaluation():
    """MODEL_CARD.md's tracking row for the shipped policy is evaluation.json's, as
    ship_policy wrote both (what the card says is what was measured)."""
    card = (SHIPPED_BEFORE.parent / "MODEL_CARD.md").read_text()
    row = next(line for line in card.splitlines() if line.startswith("| HZD-RL (es, shipped) | ") and "False" not in line)
    cells = [c.strip() for c in row.strip("|").split("|")[1:]]
    assert cells == [f"{c['error']:+.3f}" for c in _shipped_tracking()["constant"]]


@pytest.mark.parametrize("speed", [0.7, 1.1, 1.5])
def test_the_shipped_policy_walks_as_its_card_says_over_a_short_horizon(speed):
    """The shipped file still does what its card reports, on any CPU: an 8 s walk (short
    enough that the last bits of floating-point rounding, which differ between CPUs, do not
    grow into a different gait) does not fall, and its mean speed over the last 4 s is
    within 0.05 m/s of the card's 30 s figure. The card's own digits come from one machine
    and are not compared digit for digit."""
    stored = next(c for c in _shipped_tracking()["constant"] if c["speed"] == speed)
    result = walk(checkpoint_policy(SHIPPED_BEFORE), Scenario.constant(speed), 8.0)
    assert not result.failed and not stored["fell"]
    assert result.mean_speed(4.0, 8.0) == pytest.approx(stored["mean_speed_last"], abs=0.05)


@pytest.mark.slow
def test_the_model_card_opens_with_the_model_hubs_metadata_of_the_shipped_policy():
    """YAML front matter a model hub reads: licence, tags, the registered env id the policy
    was trained on, and checks 1-6's verdicts as stored in evaluation.json (ship_policy's
    ``card_header`` of the shipped checkpoint, line for line)."""
    import gymnasium
    import yaml

    from rabbit_policy.commands.ship_policy import card_header
    card = (SHIPPED_BEFORE.parent / "MODEL_CARD.md").read_text()
    assert card.startswith("---\n")
    header = card.split("---\n")[1]
    stored = json.loads((SHIPPED_BEFORE.parent / "evaluation.json").read_text())["acceptance_1_6"]
    info = checkpoint_policy(SHIPPED_BEFORE).checkpoint.info
    assert "---\n" + header + "---\n\n" == "\n".join(card_header(info, list(stored.items()))) + "\n"
    meta = yaml.safe_load(header)
    assert meta["license"] == "apache-2.0" and "reinforcement-learning" in meta["tags"]
    (result,) = meta["model-index"][0]["results"]
    env_id = result["dataset"]["type"]
    assert env_id == "RabbitHZD-Shipped-v0" and env_id in gymnasium.registry
    verdicts = {m["type"]: m["value"] for m in result["metrics"]}
    first = next(iter(stored.values()))["checks"]
    assert all(verdicts[f"check_{name}"] == ("pass" if c["passed"] else "fail") for name, c in first.items())


def test_ship_policy_refuses_a_policy_failing_checks_1_to_6_and_writes_nothing(tmp_path):
    target = SHIPPED_BEFORE
    before = target.read_bytes()
    refused = run_script("scripts/ship_policy.py", str(target), "--quick", "--dry-run", timeout=600)
    assert refused.returncode == 1, refused.stderr[-2000:]
    assert "fails acceptance checks" in refused.stderr and "not shipped" in refused.stderr
    assert "## Acceptance 1-6" in refused.stdout and "classic HZD" in refused.stdout
    for check in ("1_speed_grid", "2_transitions", "3_random_sequences", "4_pushes", "5_model_errors",
                  "6_still_hzd"):  # every check ran on the real loop, for both controllers
        row = next(line for line in refused.stdout.splitlines() if line.startswith(f"| {check.replace('_', ' ', 1)} |"))
        cells = re.split(r"(?<!\\)\|", row.strip("|"))[1:]  # a markdown row: escaped pipes stay in the cell
        assert len(cells) == 2 and not any("not measured" in c for c in cells), row
    assert "shipped with: `scripts/ship_policy.py" in refused.stdout
    assert "Constant speed, 10 s (mean hip speed over the last 5 s" in refused.stdout  # --quick: Criteria.quick()
    assert target.read_bytes() == before
    missing = run_script("scripts/ship_policy.py", str(tmp_path / "none.pt"), "--quick", "--dry-run")
    assert missing.returncode == 2 and "does not exist" in missing.stderr


def test_the_model_cards_network_paragraph_is_the_shipped_checkpoints():
    """The card's inputs, outputs and rates are what ``network_text`` renders from the shipped
    checkpoint's info (its speed integral parsed as the controller parses it)."""
    from rabbit_policy.commands.ship_policy import network_text

    card = (SHIPPED_BEFORE.parent / "MODEL_CARD.md").read_text()
    info = checkpoint_policy(SHIPPED_BEFORE).checkpoint.info
    lines = [line for line in network_text(info) if line]
    assert len(lines) >= 3 and all(line in card for line in lines), [line for line in lines if line not in card]


def test_ship_policy_sets_the_integral_rules_on_the_shipped_copy_and_the_card_says_so(tmp_path):
    """``--integral-band B``, ``--integral-windup-decay T --integral-windup-tau TAU`` and
    ``--integral-feedforward``: the copy ship_policy checks and ships holds its speed integral
    while |v_d - v| >= B (``MemoryConfig.band``), lets what it wound up after a command change
    decay (``MemoryConfig.windup_decay``) and carries the table of its steady values measured
    with those rules (``MemoryConfig.feedforward``), the network untouched; the card's inputs and regenerate line say so; a policy without the
    integral, or a value that is not a number > 0, is one line naming its option and exit 2
    before anything is measured."""
    from rabbit_policy.evaluation.steady_integral import steady_integral
    from rabbit_policy.runtime.speed_integral import WindupDecay

    from rabbit_policy.commands.ship_policy import network_text, rules_set_after_training, with_integral_rules
    trained = PolicyCheckpoint.load(SHIPPED_BEFORE)  # the network as its run left it: no rule set after
    trained.info["memory"].pop("windup_decay", None)
    trained.info["memory"].pop("feedforward", None)
    trained.info.pop("recovery_overlay", None)
    trained.save(source := tmp_path / "trained.pt")
    original = checkpoint_policy(source)
    banded = checkpoint_policy(with_integral_rules(source, tmp_path / "banded.pt", band=0.1))
    gated = checkpoint_policy(with_integral_rules(source, tmp_path / "gated.pt", windup_decay=(4.0, 0.5)))
    fed = checkpoint_policy(with_integral_rules(source, tmp_path / "fed.pt", windup_decay=(4.0, 0.5),
                                            feedforward=(1.0, 1.2)))
    assert banded.memory.config == type(banded.memory.config).from_dict({**original.memory.config.to_dict(), "band": 0.1})
    assert gated.memory.config.integral.windup_decay == WindupDecay(4.0, 0.5) and gated.memory.config.integral.band is None
    table = fed.memory.config.integral.feedforward  # measured on the copy with the decay, as steady_integrals does
    assert table.speeds == (1.0, 1.2) and table.values == tuple(round(steady_integral(gated, v), 4) for v in (1.0, 1.2))
    assert fed.memory.config.integral.windup_decay == WindupDecay(4.0, 0.5)
    for copy in (banded, gated, fed):
        assert all(torch.equal(a, b) for a, b in zip(copy.checkpoint.state_dict.values(),
                                                      original.checkpoint.state_dict.values()))
    assert "held while |v_d − v| ≥ 0.1 m/s" in " ".join(network_text(banded.checkpoint.info))
    assert "within 4 s of the change, what I wound up since the change decays with time constant 0.5 s" in " ".join(
        network_text(gated.checkpoint.info))
    flags, note = rules_set_after_training(gated.checkpoint.info)  # the card's regenerate line
    assert flags == " --integral-windup-decay 4 --integral-windup-tau 0.5" and "without the integral's windup decay" in note
    assert rules_set_after_training(banded.checkpoint.info)[0] == " --integral-band 0.1"
    flags, note = rules_set_after_training(fed.checkpoint.info)
    assert flags.endswith(" --integral-feedforward") and "windup decay and feed-forward" in note
    assert "difference of its steady values for the old and the new v_d (a feed-forward table of 2 speeds" in " ".join(
        network_text(fed.checkpoint.info))
    started = checkpoint_policy(with_integral_rules(source, tmp_path / "start.pt", feedforward=(1.0, 1.2),
                                                feedforward_start=True))
    assert started.memory.config.integral.feedforward.start and not fed.memory.config.integral.feedforward.start
    assert rules_set_after_training(started.checkpoint.info)[0] == " --integral-feedforward --integral-feedforward-start"
    assert "starts a walk at its steady value for v_d" in " ".join(network_text(started.checkpoint.info))
    assert rules_set_after_training(original.checkpoint.info) == ("", "")
    for args, message in ((["--integral-band", "0"], "--integral-band: the speed integral's band must be"),
                          (["--integral-band", "nan"], "--integral-band: the speed integral's band must be"),
                          (["--integral-windup-decay", "-1"], "--integral-windup-decay: the speed integral's windup"),
                          (["--integral-windup-decay", "5", "--integral-windup-tau", "0.01"],
                           "--integral-windup-decay: the speed integral's windup decay tau must be at least dt"),
                          (["--integral-windup-decay", "5", "--integral-band", "inf"], "--integral-band: ")):
        out = run_script("scripts/ship_policy.py", str(source), *args, "--quick", "--dry-run")
        assert out.returncode == 2 and message in out.stderr, out.stderr[-2000:]
        assert len(out.stderr.strip().splitlines()) == 1, out.stderr
    out = run_script("scripts/ship_policy.py", str(source), "--integral-feedforward-start", "--quick", "--dry-run")
    assert out.returncode == 2 and "--integral-feedforward-start needs --integral-feedforward" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1, out.stderr
    for args, message in ((["--recovery-overlay-policy-blend"], "need --recovery-overlay"),
                          (["--recovery-overlay", "--recovery-overlay-at-once", "--recovery-overlay-policy-blend"],
                           "choose one")):
        out = run_script("scripts/ship_policy.py", str(source), *args, "--quick", "--dry-run")
        assert out.returncode == 2 and message in out.stderr and len(out.stderr.strip().splitlines()) == 1, out.stderr
    trained.info.pop("memory")  # a checkpoint that keeps no integral
    trained.save(paper := tmp_path / "paper.pt")
    out = run_script("scripts/ship_policy.py", str(paper), "--integral-feedforward", "--quick", "--dry-run")
    assert out.returncode == 2 and "--integral-feedforward: " in out.stderr and "has no speed integral" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1, out.stderr


@pytest.mark.slow
def test_walk_script_runs_the_learned_policy():
    out = run_script("scripts/walk.py", "--controller", "learned", "--speed", "1.3", "--duration", "12", "--json",
                     timeout=120)
    assert out.returncode == 0, out.stderr
    summary = json.loads(out.stdout)
    assert summary["controller"] == "learned" and summary["fell"] is False
    assert summary["mean_speed"] == pytest.approx(1.3, abs=0.05)
    missing = run_script("scripts/walk.py", "--controller", "learned", "--policy-file", "/nonexistent.pt")
    assert missing.returncode == 2 and "does not exist" in missing.stderr


def _processes_with(marker: str) -> list[int]:
    """Processes whose environment holds ``marker`` (every process a command started —
    Ray's too — inherits its environment)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if marker.encode() in (entry / "environ").read_bytes():
                    found.append(int(entry.name))
            except OSError:
                continue
    return found


# both signals, both algorithms, both backends (Ray: its private instance, ES workers and PPO's
# environment actors): three runs cover every path; the other combinations repeat them
@pytest.mark.parametrize("algo, sig, backend", [("ppo", "SIGINT", "local"), ("es", "SIGINT", "ray"),
                                                ("ppo", "SIGTERM", "ray")])
@pytest.mark.slow
def test_train_stops_cleanly_on_ctrl_c_or_sigterm(tmp_path, algo, sig, backend):
    """Ctrl-C reaches the whole process group, SIGTERM only the main process: either way
    a checkpoint is written, the workers are gone (with Ray: the private instance's
    raylet, GCS and workers too) and the exit is clean."""
    import os
    import signal
    import time
    import uuid

    marker = f"RABBIT_TEST_RUN={uuid.uuid4().hex}"
    small = (["--pairs", "2", "--episodes", "1"] if algo == "es" else ["--envs", "2", "--steps", "4"])
    proc = subprocess.Popen(
        [sys.executable, "scripts/train.py", "--algo", algo, "--workers", "2", "--out", str(tmp_path / "run"),
         "--iterations", "100000", "--max-steps", "4", "--eval-every", "3", "--no-progress",
         "--warm-start", "none", "--decision-period", "0", "--distribution", "paper", "--backend", backend, *small],
        env={**os.environ, marker.split("=")[0]: marker.split("=")[1]},
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
        # as from a terminal: a suite started in the background (`cmd &` in a script) has
        # SIGINT ignored, which children inherit, and Python then installs no handler
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 120
        while not (tmp_path / "run" / "log.csv").exists() or len(read_csv(tmp_path / "run" / "log.csv")) < 2:
            assert time.monotonic() < deadline and proc.poll() is None, proc.stderr.read() if proc.poll() else ""
            time.sleep(0.2)
        if sig == "SIGINT":
            os.killpg(proc.pid, signal.SIGINT)
        else:
            proc.send_signal(signal.SIGTERM)
        _out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 128 + getattr(signal, sig), err  # interrupted, not finished: reproduce stops there
    assert "interrupted: saving a checkpoint" in _out + err and "Traceback" not in err
    state = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=False)
    assert state["algo"] == algo and state["trainer"]["env_steps"] > 0
    time.sleep(0.5)
    with pytest.raises(ProcessLookupError):
        os.killpg(proc.pid, 0)  # no worker of the group is left
    deadline = time.monotonic() + 30  # Ray's processes stop on their own after the driver's shutdown
    while _processes_with(marker) and time.monotonic() < deadline:
        time.sleep(0.5)
    assert not _processes_with(marker)


@pytest.mark.slow
def test_stopping_workers_whose_pipes_broke_exits_cleanly():
    """``pkill -f train.py`` signals the workers too: PPO's environment workers die at once
    and closing them raises ConnectionResetError in the stopper thread (seen as a traceback
    after "interrupted: saving a checkpoint"). The stop finishes quietly with the status it is given."""
    code = """
from rabbit_policy.learning.training import stop_workers
class Broken:
    def close(self, terminate=False):
        raise ConnectionResetError(104, "Connection reset by peer")
stop_workers(Broken(), Broken(), 130)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert out.returncode == 130 and "Traceback" not in out.stderr, out.stderr


def test_train_defaults_are_the_first_shipped_run_and_the_card_command_rebuilds_the_shipped_configuration():
    """CleanRL-style configuration: train.py's options come from the config dataclasses. Its
    defaults are the paper's network as first shipped (config/train/first_shipped_es.yaml:
    the three inputs, direct coefficients), and the model card's regenerate command parses
    back to the shipped checkpoint's trainer configuration."""
    import importlib
    import shlex

    train = importlib.import_module("rabbit_policy.commands.train")
    info = PolicyCheckpoint.load(SHIPPED_BEFORE).info
    defaults = train.parse_config(["--algo", "es", "--out", "runs/X"])
    first = train.parse_config(["--config", str(ROOT / "config/train/first_shipped_es.yaml"), "--out", "runs/X"])
    assert (defaults.trainer, defaults.workers, defaults.warm_start, defaults.eval_every) == (
        first.trainer, first.workers, first.warm_start, first.eval_every)
    assert (defaults.trainer.features, defaults.trainer.action) == ("paper", "direct")
    shipped = {**NEWER_FIELDS, **info["config"]}  # older files lack these
    card = (SHIPPED_BEFORE.parent / "MODEL_CARD.md").read_text()
    command = re.search(r"regenerate: `scripts/train.py ([^`]+)`", card).group(1)
    assert train.parse_config(shlex.split(command)).trainer.to_dict() == shipped


# ------------------------------------------------------------------------- presets
def _train_module():
    import importlib

    return importlib.import_module("rabbit_policy.commands.train")


def test_the_shipped_preset_is_the_shipped_policys_run_and_every_preset_parses(tmp_path):
    train = _train_module()
    preset = train.parse_config(["--config", str(ROOT / "config/train/shipped_es.yaml"), "--out", "runs/x"])
    card = (SHIPPED_BEFORE.parent / "MODEL_CARD.md").read_text()
    command = re.search(r"regenerate: `scripts/train.py (.*?) --out runs/X`", card).group(1).split()
    assert preset == train.parse_config([*command, "--out", "runs/x"])
    trained = {**NEWER_FIELDS, **checkpoint_policy(SHIPPED_BEFORE).checkpoint.info["config"]}  # what trained it
    assert preset.trainer.to_dict() == trained
    overridden = train.parse_config(["--config", str(ROOT / "config/train/shipped_es.yaml"), "--out", "runs/x",
                                     "--iterations", "3"])
    assert overridden.iterations == 3 and overridden.trainer == preset.trainer  # the command line wins
    for path in sorted((ROOT / "config" / "train").glob("*.yaml")):
        if not path.name.startswith("sb3"):
            assert train.parse_config(["--config", str(path), "--out", "runs/x"]).algo in ("es", "ppo"), path


@pytest.mark.parametrize("text, message", [("sigmaa: 0.1\n", "'sigmaa' is not a train.py option"),
                                           ("distribution: wide\n", "is not one of"),
                                           ("- a list\n", "a mapping"),
                                           ("stop_when_passed: maybe\n", "must be true or false")])
def test_a_bad_preset_is_one_line(tmp_path, capsys, text, message):
    """train.py's parser in this process (the script's own code path: parse_config); that the
    process exits 2 with that one line is checked once, through the script, below."""
    bad = tmp_path / "bad.yaml"
    bad.write_text("algo: es\n" + text if not text.startswith("-") else text)
    with pytest.raises(SystemExit) as stopped:
        _train_module().parse_config(["--config", str(bad), "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err
    assert stopped.value.code == 2 and message in err and len(err.strip().splitlines()) == 1, err


@pytest.mark.slow
def test_a_bad_preset_stops_the_script_with_one_line_and_exit_2(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("algo: es\nsigmaa: 0.1\n")
    out = run_script("scripts/train.py", "--config", str(bad), "--out", str(tmp_path / "run"))
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert "'sigmaa' is not a train.py option" in out.stderr and not (tmp_path / "run").exists()


@pytest.mark.slow
def test_a_memory_run_ships_a_policy_that_keeps_its_memory_in_every_loop(tmp_path):
    """Ablation row b through train.py: the checkpoint says its features and memory, and the
    learned policy built from it (walk.py, the evaluations, policy_node) runs the memory."""
    out = tmp_path / "memory"
    result = run_script("scripts/train.py", "--algo", "es", "--out", str(out), "--seed", "1", "--workers", "1",
                        "--pairs", "1", "--episodes", "1", "--max-steps", "20", "--decision-period", "20",
                        "--features", "memory", "--iterations", "1", "--eval-every", "0", "--warm-start",
                        "interpolate", "--no-progress")
    assert result.returncode == 0, result.stderr
    policy = make_policy("learned", policy_file=out / "policy.pt")
    assert policy.checkpoint.info["features"] == "memory" and policy.memory is not None
    assert policy.forward.inputs == 25
    walked = walk(policy, Scenario.constant(1.0), 3.0)
    assert not walked.failed and policy.memory.integral != 0.0


def test_ship_policy_ships_the_checkpoints_spec_and_a_regenerate_line_that_runs(tmp_path):
    """What ship_policy writes runs: the spec beside the checkpoint (``write_spec``) builds the
    controller the checkpoint ran as, bit for bit; the card's recipe trains as far as the files
    its screen reads, and ships with ``--allow-failing`` when the card says the checks fail."""
    from rabbit_policy.commands.ship_policy import screened_through, train_command, write_spec
    from rabbit_policy.experiment.loop import walk
    from rabbit_policy.spec import load_controller, load_spec

    write_spec(SHIPPED_BEFORE, tmp_path, "scripts/ship_policy.py X --out DIR", {"code_commit": "abc"})
    spec = load_spec(tmp_path / "learned.yaml")
    assert spec.provenance["written_by"] == "scripts/ship_policy.py X --out DIR"
    assert spec.provenance["code_commit"] == "abc"
    scenario = Scenario.constant(1.0, pushes=(Push(2.4, -120.0, 0.1),))
    shipped, checkpoint = (walk(p, scenario, 4.0, record_state=True) for p in
                           (load_controller(tmp_path / "learned.yaml"), checkpoint_policy(SHIPPED_BEFORE)))
    assert np.array_equal(shipped.qpos, checkpoint.qpos)
    info = checkpoint_policy(SHIPPED_BEFORE).checkpoint.info
    assert screened_through(info, "screen_policies.py runs/X/evaluated/{00190,00255,00320}.pt") == 320
    assert screened_through(info, "") == info["iteration"] == 255
    assert "--iterations 320 " in train_command(info, True, 320)
    card = (SHIPPED_BEFORE.parent / "MODEL_CARD.md").read_text()
    assert "--iterations 320 " in card and "--recovery-overlay-policy-blend --allow-failing`" in card
