"""scripts/reproduce.py: one command from a preset to a shipped learned controller under
--out (never into the package): train -> screen -> ship -> evaluate -> model card."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from rabbit_policy.commands.reproduce import load_preset, train_arguments
from rabbit_policy.spec.provenance import DirtyTree, code_commit, shipping_provenance
from rabbit_policy.spec import load_controller, load_spec, packaged_spec, packaged_spec_dir

pytestmark = pytest.mark.sim

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_the_tiny_preset_runs_the_chain_end_to_end_and_walk_py_walks_what_it_wrote(tmp_path):
    packaged_before = sorted(p.name for p in packaged_spec_dir().iterdir())
    out = tmp_path / "tiny"
    dirty = ["--allow-dirty"] if code_commit().endswith("+dirty") else []  # (a fresh clone, as CI's, is clean)
    run = subprocess.run([sys.executable, "scripts/reproduce.py", "--preset", "tiny", "--out", str(out), *dirty],
                         cwd=ROOT, capture_output=True, text=True, timeout=600)
    verdict = json.loads(run.stdout.strip().splitlines()[-1])  # the console's verdict line says the JSON's ...
    assert run.returncode == (0 if verdict["passed"] else 1), run.stderr[-3000:]  # ... and so does the exit status
    assert (f"verdict: ships {verdict['shipped']}; its acceptance (full criteria) "
            f"{'passed' if verdict['passed'] else 'FAILED'} ({verdict['failures']} failed checks)") in run.stdout
    assert sorted(p.name for p in packaged_spec_dir().iterdir()) == packaged_before  # nothing into the package
    spec = load_spec(out / "learned.yaml")
    assert (out / spec.network.weights.file).is_file()
    provenance = spec.provenance
    assert provenance["commands"][0] == "scripts/reproduce.py --preset tiny --out $OUT"  # no machine's paths
    assert str(out) not in str(provenance) and str(ROOT) not in str(provenance)
    assert [c.split(" --seed ")[1].split()[0] for c in provenance["commands"][2:]] == ["0", "1"]  # a run per seed
    assert all(c.startswith("scripts/train.py --algo es --spec ") for c in provenance["commands"][2:])
    assert [r["seed"] for r in provenance["runs"]] == [0, 1] and (out / "curves.png").stat().st_size > 10_000
    assert len(provenance["code_commit"]) >= 40 and len(provenance["library_sha256"]) == 64
    assert ("dirty_diff_sha256" in provenance) == bool(dirty) and provenance["machine"]["numpy"]
    evaluation = json.loads((out / "evaluation.json").read_text())
    card = (out / "MODEL_CARD.md").read_text()
    assert "scripts/reproduce.py --preset tiny --out $OUT" in card  # its regenerate line is what ran
    first = evaluation["acceptance"]["constant"][0]
    assert f"| {first['speed']:.2f} | {first['mean_speed_last']:.3f} | {first['error']:+.3f} |" in card
    assert load_controller(out / "learned.yaml").spec == spec
    screen = json.loads((out / "screen.json").read_text())
    assert [c["candidate"] for c in screen["candidates"]] == ["start", "packaged", "seed-0/run/evaluated/00001.yaml",
                                                              "seed-1/run/evaluated/00001.yaml"]
    for row in screen["candidates"]:  # every candidate on the same paired trials
        assert {k: len(v) for k, v in row["outcomes"].items()} == {"forward": 2, "backward": 2, "changes": 2}
    assert screen["select"] == "heldout"  # each seed's candidate picked on trials that are not the screen's
    for seed in (0, 1):
        [picked] = screen["selection"][f"seed-{seed}"]
        assert picked["candidate"] == f"seed-{seed}/run/evaluated/00001.yaml" and picked["of"] == 6
        assert f"select, seed {seed}: 1: {picked['passed']}/6 held-out trials passed" in run.stdout
    assert screen["level"] == 0.05 and screen["chosen_on"] == "selection"  # judged alone: chosen off the screen
    assert provenance["verdict"] == {"ships": screen["beats_start"], "why": screen["why_not"], "level": 0.05,
                                     "over_seeds": screen["over_seeds"], "chosen_on": "selection"}
    assert "trained candidate that passed most held-out selection trials" in card
    seeds = screen["over_seeds"]  # rliable's IQM over the two seeds' candidates, with its bootstrap interval
    trained = screen["candidates"][2:]
    assert seeds["candidates"] == 2 and seeds["share"]["values"] == [r["passed"] / r["of"] for r in trained]
    assert seeds["share"]["ci95"][0] <= seeds["share"]["iqm"] <= seeds["share"]["ci95"][1]
    assert f"screen trials passed {seeds['share']['iqm']:.3f}" in card and "over the 2 seeds" in run.stdout
    assert provenance["shipped"] == screen["shipped"] == (screen["best"] if screen["beats_start"] else "start")
    shipped_row = next(r for r in screen["candidates"] if r["candidate"] == screen["shipped"])
    assert evaluation["rates"] == shipped_row["rates"] and f"**Shipped: `{screen['shipped']}`.**" in card
    if screen["shipped"] == "start":  # not better: the start ships, its network a zero residual
        start = load_controller(out / "seed-0" / "start.yaml")
        assert spec.network.weights == start.spec.network.weights
    walked = subprocess.run([sys.executable, "scripts/walk.py", "--controller", "learned", "--policy-file",
                             str(out / "learned.yaml"), "--duration", "3", "--json"], cwd=ROOT, capture_output=True,
                            text=True, timeout=300)
    assert walked.returncode == 0 and json.loads(walked.stdout)["fell"] is False, walked.stderr[-2000:]
    again = subprocess.run([sys.executable, "scripts/reproduce.py", "--preset", "tiny", "--out", str(out), *dirty],
                           cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert again.returncode == 2 and "is not empty" in again.stderr
    resumed = subprocess.run([sys.executable, "scripts/reproduce.py", "--preset", "tiny", "--out", str(out),
                              "--resume", *dirty], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert resumed.returncode == run.returncode, resumed.stderr[-3000:]  # a finished training trains no further
    assert load_spec(out / "learned.yaml").network == spec.network
    assert load_spec(out / "learned.yaml").provenance["commands"][0].endswith(" --resume")


@pytest.mark.slow
def test_a_training_stopped_by_sigterm_stops_reproduce_before_its_screen(tmp_path):
    """A seed's training killed with SIGTERM writes its checkpoint and exits 143; reproduce.py
    says so in one line and exits 143 too, training no other seed and screening nothing (an
    interrupted run is not a finished one: ``--resume`` continues it)."""
    import os
    import signal
    import time

    from proc_helpers import children

    preset = yaml.safe_load((ROOT / "config/reproduce/tiny.yaml").read_text())
    preset["train"].update(iterations=100000, eval_every=100000)
    (tmp_path / "long.yaml").write_text(yaml.safe_dump(preset))
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "scripts/reproduce.py", "--preset", str(tmp_path / "long.yaml"),
                             "--out", str(out), "--allow-dirty"], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 300
        while not (out / "seed-0" / "run" / "log.csv").is_file():
            assert time.monotonic() < deadline and proc.poll() is None, proc.communicate()[1][-2000:]
            time.sleep(0.2)
        training = children(proc.pid, "rabbit_policy.commands.train")
        assert len(training) == 1
        os.kill(int(training[0]), signal.SIGTERM)
        _out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 128 + signal.SIGTERM, err[-2000:]
    assert "interrupted: training seed 0 stopped with its checkpoint; --resume continues it" in err
    assert (out / "seed-0" / "run" / "checkpoint.pt").is_file()
    assert not (out / "seed-1").exists() and not (out / "screen.json").exists()


def test_presets_are_data_with_every_key_and_bad_ones_are_one_line(tmp_path):
    for name in ("tiny", "shipped"):
        preset = load_preset(name)
        assert preset["start"] == "zero" and preset["evaluation"] in ("quick", "full")
        assert preset["screen"]["trials"] in ("quick", "full") and preset["screen"]["candidates"] >= 1
        assert preset["screen"]["select"] in ("acceptance", "heldout")
    shipped = load_preset("shipped")
    run = yaml.safe_load((ROOT / "config" / "train" / "shipped_es.yaml").read_text())
    for key in ("pairs", "episodes", "max_steps", "sigma", "lr", "weight_decay", "distribution", "fall_penalty"):
        assert shipped["train"][key] == run[key], key  # the shipped run's ES settings
    assert len(shipped["seeds"]) >= 3 and shipped["train"]["eval_every"] > 0  # seeds, each with a held-out curve
    assert train_arguments({"pairs": 2, "keep_evaluated": True, "resume": False}) == ["--pairs", "2",
                                                                                      "--keep-evaluated"]
    bad = tmp_path / "bad.yaml"
    bad.write_text("start: packaged\ntrain: {}\n")
    good = ("start: zero\nseeds: [0]\ntrain: {}\nscreen: {candidates: 1, trials: full, select: acceptance}\n"
            "evaluation: quick\n")
    cases = {"screen: {candidates: 0, trials: full, select: acceptance}": "screen is {candidates: a whole number >= 1",
             "screen: {candidates: 1, trials: full, select: best}": "select: one of ('acceptance', 'heldout')",
             "screen: {candidates: 1, trials: full}": "screen is {candidates",
             "seeds: [0, 0]": "seeds is a list of distinct whole numbers", "seeds: []": "seeds is a list",
             "train: {seed: 3}": "the seeds are the preset's seeds", "start: scratch": "start is one of"}
    presets = [("nonexistent", "no preset 'nonexistent'"), (str(bad), "must have exactly the keys")]
    for k, (line, message) in enumerate(cases.items()):
        key = line.split(":")[0]
        path = tmp_path / f"bad{k}.yaml"
        path.write_text("".join(row if not row.startswith(key + ":") else line + "\n"
                                for row in good.splitlines(keepends=True)))
        presets.append((str(path), message))
    for preset, message in presets:
        out = subprocess.run([sys.executable, "scripts/reproduce.py", "--preset", preset, "--out",
                              str(tmp_path / "x")], cwd=ROOT, capture_output=True, text=True, timeout=120)
        lines = out.stderr.strip().splitlines()
        assert out.returncode == 2 and message in lines[-1] and "Traceback" not in out.stderr, out.stderr
    assert packaged_spec("learned").is_file()


def test_the_screen_takes_the_candidates_the_training_ranks_best(tmp_path):
    """``candidates``: the evaluated specs with the fewest failed checks, then the smallest summed
    error (the start's row and files not kept left out); none evaluated: the run's last policy."""
    from rabbit_policy.commands.reproduce import candidates

    run = tmp_path / "run"
    (run / "evaluated").mkdir(parents=True)
    rows = [(0, 0, 1.0), (5, 1, 0.5), (10, 0, 1.4), (15, 0, 1.2), (20, 0, 1.1), (25, 2, 0.1)]
    lines = ["iteration,wall_s,env_steps,passed,failures,total_error,worst_speed_error,falls,slowest_reach_s"]
    lines += [f"{i},1.0,10,{f == 0},{f},{e},0.01,0,3.0" for i, f, e in rows]
    (run / "eval.csv").write_text("\n".join(lines) + "\n")
    for i, _, _ in rows:
        if i not in (0, 20):  # generation 20 was evaluated but not kept
            (run / "evaluated" / f"{i:05d}.yaml").write_text("")
    assert [p.name for p in candidates(run, 3)] == ["00015.yaml", "00010.yaml", "00005.yaml"]
    assert candidates(tmp_path / "empty", 2) == [tmp_path / "empty" / "policy.yaml"]


def test_the_verdict_judges_the_candidate_that_passed_most_selection_trials():
    """``selected_best``: among the screened candidates, most selection trials passed, then fewest
    failed checks, then the later; an unscreened one is never it; no selection: None."""
    from rabbit_policy.commands.reproduce import selected_best

    def scored(name, passed, failures, iteration):
        return {"candidate": name, "passed": passed, "failures": failures, "iteration": iteration}

    selection = {"seed-0": [scored("a", 300, 0, 10), scored("b", 305, 0, 20)],
                 "seed-1": [scored("c", 305, 0, 10), scored("d", 309, 0, 30)]}
    assert selected_best(selection, ["a", "b", "c"]) == "b"  # d was not screened; b and c tie, b is later
    assert selected_best({"seed-0": [scored("a", 300, 1, 10), scored("b", 300, 0, 5)]}, ["a", "b"]) == "b"
    assert selected_best({}, ["a"]) is None
    # a snapshot significantly worse than the start on a family ranks after every one that is not
    worse = {**scored("e", 311, 0, 40), "worse": ["forward"]}
    assert selected_best({**selection, "seed-2": [worse]}, ["a", "b", "e"]) == "b"
    assert selected_best({"start": {"passed": 312}, "seed-2": [worse]}, ["e"]) == "e"  # the start's counts are no candidate


def test_heldout_selection_picks_the_evaluated_spec_passing_most_trials_then_fewest_failed_checks(tmp_path):
    """``heldout_candidates``: every kept evaluated spec walks the held-out selection trials; the
    most passed wins, a tie goes to fewer failed acceptance checks, then to the later one."""
    import shutil

    from rabbit_policy.commands.reproduce import heldout_candidates
    from rabbit_policy.evaluation.shipping import ScreenTrials, measure
    from rabbit_policy.spec import load_controller

    run = tmp_path / "run"
    (run / "evaluated").mkdir(parents=True)
    learned = packaged_spec("learned")
    weights = learned.parent / load_spec(learned).network.weights.file
    shutil.copyfile(weights, run / "evaluated" / weights.name)
    for i in (5, 10, 15):
        shutil.copyfile(learned, run / "evaluated" / f"{i:05d}.yaml")
    lines = ["iteration,wall_s,env_steps,passed,failures,total_error,worst_speed_error,falls,slowest_reach_s",
             "0,1,0,True,0,1.0,0.01,0,3.0", "5,1,10,True,0,1.0,0.01,0,3.0", "10,1,20,False,1,0.5,0.01,0,3.0",
             "15,1,30,True,0,1.2,0.01,0,3.0"]
    (run / "eval.csv").write_text("\n".join(lines) + "\n")
    trials = ScreenTrials.selection(quick=True)
    picked, scored = heldout_candidates(run, 2, trials, map, measure(load_controller(learned), trials))
    assert [s["iteration"] for s in scored] == [5, 10, 15] and len({s["passed"] for s in scored}) == 1  # one spec
    assert all(s["worse"] == [] for s in scored)  # the start itself: no family worse
    assert [p.name for p in picked] == ["00015.yaml", "00005.yaml"]  # a tie: fewest failed checks, then the later
    assert heldout_candidates(tmp_path / "empty", 1, trials, map) == ([tmp_path / "empty" / "policy.yaml"], [])


def test_what_ships_from_a_checkout_with_uncommitted_changes_is_refused_or_records_the_diff(tmp_path):
    """shipping_provenance (reproduce.py, ship_policy.py): a clean checkout records its commit;
    one with changes is refused unless --allow-dirty, which records the hash of its diff."""
    def git(*args: str) -> None:
        subprocess.run(["git", "-c", "user.email=t@t", "-c", "user.name=t", *args], cwd=tmp_path, check=True,
                       capture_output=True)

    git("init", "-q")
    (tmp_path / "a.txt").write_text("one\n")
    git("add", "a.txt")
    git("commit", "-q", "-m", "one")
    clean = shipping_provenance(False, tmp_path)
    assert len(clean["code_commit"]) == 40 and "dirty_diff_sha256" not in clean and clean["machine"]["cpu"]
    (tmp_path / "a.txt").write_text("two\n")
    with pytest.raises(DirtyTree, match="--allow-dirty"):
        shipping_provenance(False, tmp_path)
    dirty = shipping_provenance(True, tmp_path)
    assert dirty["code_commit"] == clean["code_commit"] + "+dirty" and len(dirty["dirty_diff_sha256"]) == 64
    (tmp_path / "a.txt").write_text("three\n")
    assert shipping_provenance(True, tmp_path)["dirty_diff_sha256"] != dirty["dirty_diff_sha256"]
