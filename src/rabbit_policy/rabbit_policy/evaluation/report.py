"""``report.md`` from the evaluation's ``results.json`` dict: tables and links to the
figures and videos (file names relative to the report)."""

from __future__ import annotations

from statistics import median

from rabbit_policy.evaluation.acceptance import broad_table
from rabbit_policy.evaluation.figures import LABELS
from rabbit_policy.evaluation.statistics import format_rate, mcnemar_exact, rate


def _fmt(value, spec: str = ".3f", none: str = "—") -> str:
    return none if value is None else format(value, spec)


def _label(name: str) -> str:
    return LABELS.get(name, name)


def _outcome(result: dict) -> str:
    """"fell at 4.21 s", "stalled at 6.00 s" (no touchdown for 2 s) or "walked on"."""
    if result["fell"]:
        return f"fell at {result['fall_time']:.2f} s"
    if result["stalled"]:
        return f"stalled at {result['stall_time']:.2f} s"
    return "walked on"


def tracking_section(tracking: dict, config: dict) -> list[str]:
    lines = ["## Speed tracking", "",
             f"Filtered hip speed (moving average over {config['filter_window_s']} s) while the commanded speed "
             "steps through the schedule below (paper Fig. \"change_vel\"). Mean error: mean |filtered − "
             "commanded| over the segment. Settling: time until the filtered speed stays within "
             f"{config['tolerance_mps']} m/s for the rest of the segment. Reach: first whole step whose mean "
             f"speed is within {config['tolerance_mps']} m/s (the acceptance definition).", "",
             "![speed tracking](tracking.png)", ""]
    for name, result in tracking.items():
        fell = f", **{_outcome(result)}**" if result["outcome"] != "walked" else ", no fall"
        lines += [f"**{_label(name)}** ({result['policy']}{fell})", "",
                  "| segment (s) | command (m/s) | mean error (m/s) | 2nd-half mean error (m/s) | settling (s) | reach (s) |",
                  "|---|---|---|---|---|---|"]
        for seg in result["segments"]:
            lines.append(f"| {seg['start']:.0f}–{seg['end']:.0f} | {seg['speed']:.2f} | {_fmt(seg['mean_abs_error'])} | "
                         f"{_fmt(seg['mean_error_second_half'], '+.3f')} | {_fmt(seg['settling_time'], '.2f')} | "
                         f"{_fmt(seg['reach_time'], '.2f')} |")
        lines.append("")
    return lines


def limit_cycle_section(cycles: dict, config: dict) -> list[str]:
    push = config["portrait_push"]
    lines = ["## Limit cycles", "",
             f"Phase portraits of the left hip and knee over {config['portrait_duration_s']:.0f} s of walking, "
             f"perturbed once by a {push['force_x_N']:+.0f} N push of {push['duration_s']} s at "
             f"{push['time_s']} s: the transient (grey) returns to the closed orbit (red, the last 5 s; the "
             "right leg runs the same orbit one step later) "
             "(paper Fig. \"limit_cycle\"). The convergence plot shows, per step, the distance of the "
             "joint state 20 ms after touchdown (stance-relative, rates weighted 1/10 s) from the mean of "
             "the last six steps; it shrinks to the walk's own step-to-step jitter. Settled: the first "
             "step from which it stays within 5x that jitter.", ""]
    for name in cycles:
        lines += [f"![limit cycles, {_label(name)}](limit_cycle_{name}.png)", ""]
    lines += ["![convergence](convergence.png)", "",
              "| controller | speed (m/s) | outcome | steps | jitter | settled at step |", "|---|---|---|---|---|---|"]
    for name, by_speed in cycles.items():
        for speed, result in sorted(by_speed.items()):
            lines.append(f"| {_label(name)} | {float(speed):.1f} | {_outcome(result)} | {result['steps']} | "
                         f"{_fmt(result['jitter'], '.4f')} | {_fmt(result['settled_step'], 'd')} |")
    return lines + [""]


def poincare_section(poincare: dict) -> list[str]:
    lines = ["## Poincaré test", "",
             "The step-to-step return map at mid-stance (stance phase 0.5, interpolated between ticks), its "
             "Jacobian at the cycle by least-squares central differences over random symmetric "
             "perturbations (the full MuJoCo state and the controller restored for every perturbed "
             "run; `rabbit_policy.evaluation.stability`). Classic HZD: 10 coordinates (torso pitch, four "
             "stance-relative joints, their rates). HZD-RL has memory (the gait in force, the queued "
             "gait and the running step mean all depend on measured speeds), so its map has three more "
             "coordinates. Stable when every |λ| < 1; the largest |λ| is the factor by which a small "
             "perturbation shrinks per step. `decay` is the same factor measured by walking a "
             "perturbation along the slowest eigenvector (— when it vanished into the walk's own "
             "step-to-step jitter within three steps). Each row is the median of analyses under several "
             "perturbation seeds (`section_iv.POINCARE_SEEDS`), the seeds' largest |λ| in brackets: one "
             "analysis moves by 0.1-0.25 from seed to seed, so differences below about 0.15 are noise.", "",
             "![eigenvalue magnitudes](poincare.png)", "",
             "| controller | speed (m/s) | dim | largest \\|λ\\| | all \\|λ\\| | stable | decay/step | pairs used (failed) |",
             "|---|---|---|---|---|---|---|---|"]
    for name, by_speed in poincare.items():
        for speed, result in sorted(by_speed.items()):
            if "error" in result:
                lines.append(f"| {_label(name)} | {float(speed):.1f} | — | — | error: {result['error']} | False | — | — |")
                continue
            mags = ", ".join(f"{m:.2f}" for m in result["magnitudes"])
            seeds = ", ".join(f"{m:.2f}" for m in result.get("largest_by_seed", []))
            lines.append(f"| {_label(name)} | {float(speed):.1f} | {result['dimension']} | {result['largest']:.3f}"
                         f"{f' ({seeds})' if seeds else ''} | "
                         f"{mags} | {result['stable']} | {_fmt(result['decay_per_step'], '.2f')} | "
                         f"{result['pairs_used']} ({result['pairs_failed']}) |")
    return lines + [""]


def _against_margins(impulse: float, sweep: dict) -> str:
    """Where a signed impulse (N s) lies against each controller's largest survived
    impulse in the same direction."""
    direction = "forward" if impulse > 0 else "backward"
    margins = [by_direction[direction]["largest_survived_Ns"] for by_direction in sweep.values()]
    if not margins:
        return "—"
    if abs(impulse) <= min(margins):
        return f"inside every controller's {direction} margin (≥ {min(margins):g} N s)"
    if abs(impulse) > max(margins):
        return f"beyond every controller's {direction} margin (≤ {max(margins):g} N s)"
    return f"between the controllers' {direction} margins ({min(margins):g}–{max(margins):g} N s)"


def repeated_section(repeated: dict, config: dict | None) -> list[str]:
    """The repeated-push table: trials survived per controller, speed and impulse."""
    if not repeated or not config:
        return []
    cells = [(speed, impulse) for speed, impulses in config["impulses_Ns"].items() for impulse in impulses]
    trials = len(config["first_times_s"])
    lines = ["### Repeated pushes (beyond the paper)", "",
             f"{config['count']} equal backward pushes of {config['push_duration_s']} s, {config['spacing_s']:g} s apart "
             f"(the shape of the paper's scenarios), the first at each of "
             f"{', '.join(f'{t:g}' for t in config['first_times_s'])} s; a trial survives when the walk neither "
             f"falls nor stalls within {config['horizon_s']:g} s. Trials survived of {trials} per speed (m/s) "
             "and impulse (N s):", "",
             "| controller | " + " | ".join(f"{float(s):.1f} m/s, {i:g} N s" for s, i in cells) + " | all |",
             "|---|" + "---|" * (len(cells) + 1)]
    for name, result in repeated.items():
        counts = [result["by_speed"][speed][f"{impulse:g}"] for speed, impulse in cells]
        lines.append(f"| {_label(name)} | " + " | ".join(str(c) for c in counts)
                     + f" | {result['survived']}/{result['trials']} |")
    return lines + [""]


def push_section(push: dict, sweep: dict, videos: list[dict]) -> list[str]:
    lines = ["## Push recovery", "",
             f"Walking at {push['speed']} m/s, a horizontal force on the torso's centre of mass at the times "
             "below (paper Figs. 5–7; the paper gives no magnitudes, these are ours; the last column "
             "places each against the impulse sweep below). Shaded: the pushes. "
             "A walk fails when the robot falls (|torso pitch| ≥ 0.5 rad or hip height outside (0.6, 0.8) m) "
             "or stalls (no touchdown for 2 s: stopped upright, legs apart).", "",
             "| scenario | force (N) | duration (s) | impulse (N s) | at (s) | vs the sweep's margins |",
             "|---|---|---|---|---|---|"]
    for s in push["scenarios"]:
        lines.append(f"| {s['name']} | {s['force_x_N']:+.0f} | {s['duration_s']} | {s['impulse_Ns']:+.1f} | "
                     f"{', '.join(f'{t:g}' for t in s['times_s'])} | {_against_margins(s['impulse_Ns'], sweep)} |")
    names = [k for k in push["table"][0] if k != "scenario"] if push["table"] else []
    lines += ["", "![push recovery](push.png)", "",
              "| scenario | " + " | ".join(_label(n) for n in names) + " |", "|---|" + "---|" * len(names)]
    for row in push["table"]:
        cells = [_outcome(row[n]) for n in names]
        lines.append(f"| {row['scenario']} | " + " | ".join(cells) + " |")
    if sweep:
        lines += ["", "### Impulse sweep (beyond the paper)", "",
                  "One push of growing impulse (fixed duration) at several times spread over about one step; "
                  "a walk survives when it has not fallen a few seconds later. \"Largest\" is the largest grid "
                  "impulse such that it and every smaller one were survived at every push time.", "",
                  "![impulse sweep](sweep.png)", "",
                  "| controller | largest backward (N s) | largest forward (N s) |", "|---|---|---|"]
        for name, result in sweep.items():
            lines.append(f"| {_label(name)} | {result['backward']['largest_survived_Ns']:.1f} | "
                         f"{result['forward']['largest_survived_Ns']:.1f} |")
    if videos:
        lines += ["", "### Videos", ""]
        for entry in videos:
            what = f"{_label(entry['controller'])}, {entry['scenario'].replace('_', ' ')} pushes"
            if "file" in entry:
                lines.append(f"- {what}: [{entry['file']}]({entry['file']})")
            else:
                lines.append(f"- {what}: not rendered ({entry['error']})")
    return lines + [""]


def neighbourhood_section(rates: dict) -> list[str]:
    """The push scenarios as rates over their neighbourhoods, with the paired tests."""
    if not rates:
        return []
    config = rates["config"]
    shifts, speeds = config["shifts_s"], config["speeds_mps"]
    names = list(rates["rates"])
    scenarios = list(rates["rates"][names[0]])
    lines = ["### The scenarios over their neighbourhoods", "",
             f"One point of a scenario is an anecdote: each is walked {len(shifts) * len(speeds)} times, its pushes "
             f"shifted together by each of {', '.join(f'{s:+g}' for s in shifts)} s (a span of "
             f"{max(shifts) - min(shifts):g} s, so the pushes land across a step) at {', '.join(f'{v:g}' for v in speeds)} m/s, "
             f"each walk {config['duration_s']:g} s. Walked k of n, with the 95 % Wilson interval:", "",
             "| scenario | " + " | ".join(_label(n) for n in names) + " |", "|---|" + "---|" * len(names)]
    for scenario in scenarios:
        lines.append(f"| {scenario} | " + " | ".join(format_rate(rates["rates"][n][scenario]) for n in names) + " |")
    if rates.get("paired_with_learned"):
        lines += ["", "Learned against each other controller on the same trials (McNemar's exact test: the trials "
                  "only one of the two walked, and the two-sided p-value):", "",
                  "| scenario | " + " | ".join(f"vs {_label(n)}" for n in names if n != "learned") + " |",
                  "|---|" + "---|" * (len(names) - 1)]
        for scenario, tests in rates["paired_with_learned"].items():
            lines.append(f"| {scenario} | " + " | ".join(
                f"learned only {t['only_a']}, {_label(n)} only {t['only_b']}, p = {t['p_value']:.2g}"
                for n, t in tests.items()) + " |")
    return lines + [""]


def _span(values: list[float]) -> str:
    return f"{min(values):g}-{max(values):g}"


def trial_outcomes(results: dict) -> dict[str, dict[str, list[bool]]]:
    """Per headline claim and controller, every trial's outcome in one order for all
    controllers (so they can be paired): ordered speed changes passed at every phase, random
    command sequences walked, model cases walked, and each push scenario walked over its
    neighbourhood."""
    claims: dict[str, dict[str, list[bool]]] = {}
    robustness = results.get("robustness") or {}
    if robustness:
        claims["ordered speed changes reached within the time limit at every phase"] = {
            n: [p["passed"] for p in r["transitions"]["pairs"]] for n, r in robustness.items()}
        claims["random one-minute command sequences without a fall or stall"] = {
            n: [row["outcome"] == "walked" for row in r["random_sequences"]["rows"]] for n, r in robustness.items()}
        claims["model cases walked (each model error at each speed)"] = {
            n: [row["outcome"] == "walked" for row in r["model_errors"]["rows"]] for n, r in robustness.items()}
        for direction in ("backward", "forward"):
            curves = {n: next((c for c in r.get("survival", []) if c["direction"] == direction), None)
                      for n, r in robustness.items()}
            if all(curves.values()):
                first = next(iter(curves.values()))
                claims[f"{direction} pushes survived over the impulse grid ({_span(first['impulses_Ns'])} N s, "
                       f"{_span(first['speeds'])} m/s, {len(first['phases'])} phases)"] = {
                    n: [o for row in c["outcomes"] for o in row] for n, c in curves.items()}
    neighbourhood = results["push"].get("neighbourhood") or {}
    for name, by_scenario in neighbourhood.get("outcomes", {}).items():
        for scenario, outcomes in by_scenario.items():
            claims.setdefault(f"the paper's `{scenario}` pushes walked, over their neighbourhood", {})[name] = outcomes
    return claims


def headline_rates(results: dict) -> dict[str, dict[str, dict]]:
    """The headline claims as rates per claim and controller (:func:`.statistics.rate`): those
    of :func:`trial_outcomes`, and repeated pushes survived (counted, not kept per trial)."""
    claims = {claim: {n: rate(o) for n, o in by_name.items()} for claim, by_name in trial_outcomes(results).items()}
    for name, repeated in (results.get("repeated_pushes") or {}).items():
        claims.setdefault("repeated pushes survived (3 backward pushes 2 s apart)", {})[name] = rate(
            [True] * repeated["survived"] + [False] * (repeated["trials"] - repeated["survived"]))
    return claims


def paired_section(results: dict) -> list[str]:
    """The learned controller against each other one on the same trials of every claim
    (McNemar's exact test)."""
    claims = trial_outcomes(results)
    names = [n for n in results["meta"]["controllers"] if n != "learned"]
    if not claims or "learned" not in results["meta"]["controllers"]:
        return []
    lines = ["## Paired comparisons", "",
             "The learned controller against each other one on the same trials: the trials only one of the two "
             "passed, and McNemar's exact two-sided p-value (a difference is significant at the 5 % level when "
             "p < 0.05).", "",
             "| claim | " + " | ".join(f"learned vs {_label(n)}" for n in names) + " |", "|---|" + "---|" * len(names)]
    for claim, by_name in claims.items():
        cells = []
        for n in names:
            t = mcnemar_exact(by_name["learned"], by_name[n])
            cells.append(f"{t['only_a']} vs {t['only_b']}, p = {t['p_value']:.2g}")
        lines.append(f"| {claim} | " + " | ".join(cells) + " |")
    return lines + [""]


SHORT_LABELS = (("ordered speed changes", "speed changes"), ("random one-minute", "1-min sequences"),
                ("model cases", "model cases"), ("backward pushes survived", "backward pushes"),
                ("forward pushes survived", "forward pushes"), ("repeated pushes", "repeated pushes"))
"""A headline claim's row label in README's table: the claim's opening words, then its label (the
paper's scenarios are labelled by their names); the legend under the table gives each claim in full."""


def short_label(claim: str) -> str:
    """The row label of the headline ``claim`` (:data:`SHORT_LABELS`; a paper scenario: its name)."""
    if claim.startswith("the paper's `"):
        return claim.split("`")[1]
    return next((label for start, label in SHORT_LABELS if claim.startswith(start)), claim)


def compact_rate(r: dict) -> str:
    """``k/n [low-high]``: a rate and its 95 % interval in %, as README's table prints it."""
    low, high = r["ci95"]
    return f"{r['k']}/{r['n']} [{100 * low:.0f}-{100 * high:.0f}]"


def headline_table(results: dict) -> list[str]:
    """README's results table, rendered from ``results.json`` (a docs test holds README to it):
    the headline rates with their 95 % intervals, then the push margins, each row by a short label
    (no line over 120 characters), and under it the legend that says each row in full."""
    import textwrap

    claims = headline_rates(results)
    names = list(results["meta"]["controllers"])
    lines = ["| | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    said: dict[str, list[str]] = {}  # a claim in full (its direction or scenario left out) -> its rows
    for claim, by_name in claims.items():
        label = short_label(claim)
        lines.append(f"| {label} | " + " | ".join(compact_rate(by_name[n]) for n in names) + " |")
        general = claim.replace(f" `{label}`", "").removeprefix("backward ").removeprefix("forward ")
        said.setdefault(general, []).append(label)
    legend = [f"*{' / '.join(labels)}*: {general}" for general, labels in said.items()]
    robustness = results.get("robustness") or {}
    if robustness and all(r.get("survival") for r in robustness.values()):
        for direction in ("backward", "forward"):
            at = {n: next(c for c in r["survival"] if c["direction"] == direction)["at_90"] for n, r in robustness.items()}
            lines.append(f"| {direction} at 90 % | "
                         + " | ".join(f"{at[n]['impulse_Ns']:g} [{at[n]['low_Ns']:g}-{at[n]['high_Ns']:g}]"
                                      for n in names) + " |")
        legend.append("*backward / forward at 90 %*: the push (N s) survived in 90 % of trials, its range from the "
                      "95 % intervals")
    if robustness:
        speeds = []
        for direction in ("backward", "forward"):
            margins = {n: {m["speed"]: m for m in r["push_margins"] if m["direction"] == direction}
                       for n, r in robustness.items()}
            speeds = sorted(margins[names[0]])
            lines.append(f"| {direction} margins | " + " | ".join(
                " / ".join(f"{margins[n][v]['largest_survived_Ns']:g}" + ("+" if margins[n][v]["capped"] else "")
                           for v in speeds) for n in names) + " |")
        legend.append(f"*backward / forward margins*: the largest push (N s) survived at every phase, at "
                      f"{' / '.join(f'{v:g}' for v in speeds)} m/s (the worst phase, no interval: the 90 % rows have one)")
    text = ("Rows: " + "; ".join(legend) + ". Each rate is trials passed of trials run [its 95 % Wilson interval, "
            "in %].")
    return lines + [""] + textwrap.wrap(text, 110, break_on_hyphens=False)


def _seed_range(poincare: dict) -> str:
    """`` [0.89–0.96]``: the range of a Poincaré analysis's largest |λ| over its perturbation
    seeds ('' with fewer than two)."""
    seeds = [v for v in poincare.get("largest_by_seed") or [] if v is not None]
    return f" [{min(seeds):.2f}–{max(seeds):.2f}]" if len(seeds) > 1 else ""


def summary_section(results: dict) -> list[str]:
    """Headline facts computed from the results (no hand-written numbers)."""
    lines = ["## Summary", ""]
    if results.get("robustness"):
        if all(r.get("survival") for r in results["robustness"].values()):
            lines += ["![survival against impulse: backward and forward pushes at every phase, 95 % bands]"
                      "(survival.png)", ""]
        lines += ["![push margins per speed: backward and forward, every phase](margins.png)", "",
                  "![model errors: walked (green, the speed error), stalled (orange), fell (red)](model_cases.png)",
                  ""]
    for name, tracking in results["tracking"].items():
        errors = [abs(seg["mean_error_second_half"]) for seg in tracking["segments"]
                  if seg["mean_error_second_half"] is not None]
        settle = [seg["settling_time"] for seg in tracking["segments"]]
        known = [t for t in settle if t is not None]
        walked = "without a fall" if tracking["outcome"] == "walked" else _outcome(tracking)
        lines.append(f"- {_label(name)}: speed tracking {walked}, second-half |error| over the {len(errors)} segments "
                     f"median {median(errors):.3f}, range {min(errors):.3f}–{max(errors):.3f} m/s, "
                     f"settling {min(known):.1f}–{max(known):.1f} s"
                     + (f" ({settle.count(None)} segment(s) never settled)" if None in settle else "")
                     if errors and known else f"- {_label(name)}: speed tracking {walked}")
    for name, by_speed in results["poincare"].items():
        stable = all(r.get("stable") for r in by_speed.values())
        lines.append(f"- {_label(name)}: walking cycle {'stable' if stable else 'NOT stable'} at every speed tested; "
                     "largest |λ| (median [range] over the perturbation seeds) "
                     + ", ".join(f"{_fmt(r.get('largest'), '.2f')}{_seed_range(r)} at {float(k):.1f} m/s"
                                 for k, r in sorted(by_speed.items())))
    for claim, by_name in headline_rates(results).items():
        lines.append(f"- {claim}: " + ", ".join(f"{_label(n)} {format_rate(r)}" for n, r in by_name.items()))
    times = results.get("config", {}).get("sweep") or {}
    for name, sweep in results.get("push_sweep", {}).items():  # (not the 8-phase margins: another grid of times)
        lines.append(f"- {_label(name)}: the impulse sweep at {results['push']['speed']:g} m/s (a push at each of "
                     f"{len(times.get('push_times_s', []))} times over a step) survived up to "
                     f"{sweep['backward']['largest_survived_Ns']:.0f} N s backward and "
                     f"{sweep['forward']['largest_survived_Ns']:.0f} N s forward")
    return lines + [""]


def _model(model) -> str:
    """``paper`` or ``drives, friction 0.4, torso mass x1.15``."""
    if isinstance(model, str):
        return f"`{model}`"
    extras = ([f"friction {model['friction']}"] if model.get("friction") is not None else []) + (
        [f"torso mass x{model['torso_mass_scale']}"] if model.get("torso_mass_scale", 1.0) != 1.0 else [])
    return "`" + ", ".join([model["variant"], *extras]) + "`"


def robustness_section(robustness: dict) -> list[str]:
    """The broad evaluation (:mod:`.robustness`): one table, then the failures by name."""
    if not robustness:
        return []
    names = list(robustness)
    lines = ["## Robustness: every speed, every change, random commands, pushes at every phase, model errors", "",
             "Definitions in `rabbit_policy/evaluation/robustness.py`.", "",
             "![ordered speed changes: passed at every phase (green), slow (orange), fell or stalled (red)]"
             "(transitions.png)", "",
             "| check | " + " | ".join(_label(n) for n in names) + " |", "|---|" + "---|" * len(names)]

    def row(title: str, cell) -> None:
        lines.append(f"| {title} | " + " | ".join(cell(robustness[n]) for n in names) + " |")

    row("speed grid: passed (|error| ≤ tolerance, no fall/stall)",
        lambda r: f"{r['speed_grid']['passed']}/{r['speed_grid']['total']}, worst error "
                  f"{_fmt(r['speed_grid']['worst_error'])} m/s")
    row("speed grid: fell or stalled at", lambda r: _speeds(r["speed_grid"]["fell_or_stalled"]))
    row("ordered changes passed (every phase)",
        lambda r: f"{r['transitions']['passed']}/{r['transitions']['total']} "
                  f"({r['transitions']['fell_or_stalled']} fell or stalled)")
    row("random sequences without fall/stall",
        lambda r: f"{r['random_sequences']['passed']}/{r['random_sequences']['total']}")
    for margin in robustness[names[0]]["push_margins"]:
        speed, direction = margin["speed"], margin["direction"]
        row(f"push margin, {speed:.1f} m/s {direction} (N s, every phase)",
            lambda r, s=speed, d=direction: next(
                f"{m['largest_survived_Ns']}" + ("+" if m["capped"] else "") for m in r["push_margins"]
                if m["speed"] == s and m["direction"] == d))
    cases = list(dict.fromkeys(x["case"] for x in robustness[names[0]]["model_errors"]["rows"]))
    for case in cases:
        row(f"model: {case} (error m/s at " + ", ".join(
            f"{x['speed']:.1f}" for x in robustness[names[0]]["model_errors"]["rows"] if x["case"] == case) + ")",
            lambda r, c=case: ", ".join(x["outcome"] if x["error"] is None else f"{x['error']:+.3f}"
                                        for x in r["model_errors"]["rows"] if x["case"] == c))
    return lines + [""]


def acceptance_section(verdicts: dict) -> list[str]:
    """The learning issue's checks 1-6 (``acceptance.judge``) per controller."""
    if not verdicts:
        return []
    names = list(verdicts)
    checks = list(verdicts[names[0]]["checks"])
    lines = ["## Acceptance checks 1-6 (the learning issue)", "",
             "Judged by `rabbit_policy.evaluation.acceptance.judge` on the results above; push margins against "
             "classic HZD's (twice where classic survives less than 15 N s), the paper's three push scenarios at "
             "1.0 m/s beyond classic's margin, model errors, Poincaré |λ| < 1 and torques.", "",
             "| check | " + " | ".join(_label(n) for n in names) + " |", "|---|" + "---|" * len(names)]
    for check in checks:
        lines.append(f"| {check.replace('_', ' ', 1)} | " + " | ".join(
            "pass" if verdicts[n]["checks"][check]["passed"] else "**fail**" for n in names) + " |")
    return lines + [""]


def load_comparisons(paths) -> dict:
    """The checks 1-6 of ``scripts/compare_policies.py --out`` files, for the report's ablation
    section: classic HZD once (from the first file: every file measures it as the reference),
    then every other controller of every file, by its column name; a name that comes again
    from another file with other results gets a column of its own, named ``name (file stem)``.
    Raises ``ValueError`` naming a file that is not such an output."""
    import json
    from pathlib import Path

    columns: dict = {}
    for path in paths:
        try:
            results = json.loads(Path(path).read_text())["results"]
            for name, result in results.items():
                column = {"policy": result["policy"], "checks": result["checks"], "passed": result["passed"],
                          "source": str(path)}
                if name in columns and (name == "classic HZD" or columns[name]["checks"] == column["checks"]):
                    continue
                columns[name if name not in columns else f"{name} ({Path(path).stem})"] = column
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
            raise ValueError(f"{path} is not a scripts/compare_policies.py --out file "
                             f"({type(exc).__name__}: {str(exc)[:120]})") from None
    return columns


def ablation_section(ablation: dict) -> list[str]:
    """Checks 1-6 of the learning issue's ablation (``--ablation``: ``scripts/compare_policies.py``
    outputs), one column per controller, with its headline figures."""
    if not ablation:
        return []
    sources = sorted({c["source"] for c in ablation.values()})
    return ["## The ablation: checks 1-6 per trained row (the learning issue)", "",
            "Measured by `scripts/compare_policies.py` (every speed, every ordered change at every phase, 100 random "
            "command sequences, push margins at every phase against classic's, model errors, Poincaré), from "
            + ", ".join(f"`{s}`" for s in sources) + "; rows and budgets in docs/learning.md.", "",
            *broad_table(list(ablation.items())), ""]


def _speeds(speeds: list[float]) -> str:
    return "none" if not speeds else ", ".join(f"{v:.2f}" for v in speeds)


def render_report(results: dict) -> str:
    """The whole report as Markdown."""
    meta = results["meta"]
    lines = ["# rabbit-hzd evaluation: " + " vs ".join(_label(n) for n in results["meta"]["controllers"]), "",
             f"Generated by `{meta['command']}` in {meta['wall_time_s']:.0f} s wall time "
             f"({meta['workers']} worker processes), model {_model(meta['model'])}, on the ROS-free fast path "
             "(the nodes' MuJoCo model and HZD controller, no ROS). Every number is in `results.json`.", "",
             "| controller | policy |", "|---|---|"]
    for name, policy in meta["controllers"].items():
        lines.append(f"| {_label(name)} | {policy} |")
    lines.append("")
    lines += summary_section(results)
    lines += paired_section(results)
    lines += tracking_section(results["tracking"], results["config"])
    lines += limit_cycle_section(results["limit_cycle"], results["config"])
    lines += poincare_section(results["poincare"])
    lines += push_section(results["push"], results.get("push_sweep", {}), results.get("videos", []))
    lines += neighbourhood_section(results["push"].get("neighbourhood") or {})
    lines += repeated_section(results.get("repeated_pushes", {}), results["config"].get("repeated"))
    lines += robustness_section(results.get("robustness", {}))
    lines += acceptance_section(results.get("acceptance_1_6", {}))
    if results.get("ablation"):
        lines += ["The checks 1-6 of the trained ablation rows (`--ablation`) are in [ablation.md](ablation.md), "
                  "with the research log (docs/learning.md).", ""]
    return "\n".join(lines)


def render_ablation(results: dict) -> str:
    """``--ablation``'s table as a page of its own (``ablation.md``)."""
    return "\n".join(["# The ablation: checks 1-6 per trained row", "",
                      f"Written by `{results['meta']['command']}` beside report.md.", "",
                      *ablation_section(results["ablation"])[2:]])
