"""Learning probe (issue 72): the ten-seed screen-guarded preset judged as reproduce.py judges it,
without recomputing seeds 0-4 (their selection counts and screen outcomes are in the five-seed
run's screen.json, the same code): seeds 5-9's selection on the held-out trials (against the
start's, measured again for its outcomes), the judged network among all ten (most selection
trials, reproduce.selected_best), seeds 5-9's networks on the 940 screen trials, the judged one's
paired test against the start (and its acceptance checks when it is a new one), and the IQM over
the ten seeds (shipping.over_seeds)."""
import json
import sys
import time
from pathlib import Path

from rabbit_msgs_py import strict_json
from rabbit_policy.commands.reproduce import heldout_candidates, measure_candidate, selected_best
from rabbit_policy.evaluation.acceptance import Criteria
from rabbit_policy.evaluation.shipping import ScreenTrials, measure, over_seeds, verdict
from rabbit_policy.parallel import LocalBackend
from rabbit_policy.spec import load_controller

OLD, NEW = Path(sys.argv[1]), Path(sys.argv[2])
old = json.loads((OLD / "screen.json").read_text())
backend = LocalBackend(2)
held_out = ScreenTrials.selection(quick=False)
start_path = NEW / "seed-0" / "start.yaml"
start_sel = measure(load_controller(start_path), held_out, backend.map)
assert start_sel["passed"] == old["selection"]["start"]["passed"], "the start's selection moved"
print(f"select, the start: {start_sel['passed']}/{start_sel['of']}", flush=True)
selection = dict(old["selection"])
picked = {}
for seed in range(5, 10):
    run = NEW / f"seed-{seed}" / "run"
    while not (run / "summary.json").is_file() or json.loads((run / "summary.json").read_text())["info"][
            "iteration"] < 30:  # the seed still trains (its summary is written at every checkpoint)
        time.sleep(20)
    paths, scored = heldout_candidates(run, 1, held_out, backend.map, start_sel)
    selection[f"seed-{seed}"] = [{**s, "candidate": str(s["candidate"].relative_to(NEW))} for s in scored]
    picked[str(paths[0].relative_to(NEW))] = paths[0]
    print(f"select, seed {seed}: " + ", ".join(f"{s['iteration']}: {s['passed']}/{s['of']}"
                                                + (f" ({', '.join(s['worse'])} worse)" if s["worse"] else "")
                                                for s in scored) + f"; {paths[0].relative_to(NEW)}", flush=True)
start_row = old["candidates"][0]
old_trained = [r for r in old["candidates"] if r["candidate"] not in ("start", "packaged")]
names = [r["candidate"] for r in old_trained] + list(picked)
judged = selected_best(selection, names)
print(f"judged (most selection trials among the ten): {judged}", flush=True)
rows = []
for name, path in picked.items():
    row = ({"candidate": name, **measure_candidate(path, Criteria(), ScreenTrials(), backend.map)} if name == judged
           else {"candidate": name, "failures": None, **measure(load_controller(path), ScreenTrials(), backend.map)})
    rows.append(row)
    print(f"screen {name}: " + ", ".join(f"{f} {sum(o)}/{len(o)}" for f, o in row["outcomes"].items())
          + f", all {row['passed']}/{row['of']}", flush=True)
trained = old_trained + rows
best = next(r for r in trained if r["candidate"] == judged)
ships, why, tests = verdict(best, start_row, screened=1)
seeds = over_seeds(trained, start_row)
print(f"verdict: ships {ships}; {why}; all {tests['all']}", flush=True)
print(f"over the {seeds['candidates']} seeds: share IQM {seeds['share']['iqm']:.4f} {seeds['share']['ci95']}, "
      f"start {seeds['start_share']:.4f}; gain IQM {seeds['gain_over_start']['iqm']:+.4f} "
      f"{seeds['gain_over_start']['ci95']}; gains {[round(g, 4) for g in seeds['gain_over_start']['values']]}", flush=True)
(NEW / "probe_ten.json").write_text(strict_json.dumps({
    "judged": judged, "ships": ships, "why_not": why, "tests": tests, "over_seeds": seeds,
    "new_rows": [{k: v for k, v in r.items() if k != "acceptance"} for r in rows], "selection": selection}, indent=2) + "\n")
backend.close()
