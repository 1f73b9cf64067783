"""The evaluation's figures (PNG, matplotlib's Agg backend: no display needed).

Each function draws one figure from :mod:`.section_iv`' results (the dicts that go to
``results.json``; the phase portraits also need the recorded walks) and saves it.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from rabbit_policy.experiment.result import WalkResult  # noqa: E402

COLORS = {"classic": "tab:blue", "learned": "tab:orange", "recovery": "tab:green", "classic_integral": "tab:purple",
          "network_alone": "tab:brown"}
LABELS = {"classic": "classic HZD", "learned": "HZD-RL (learned)", "recovery": "recovery (model-based)",
          "classic_integral": "classic + speed integral", "network_alone": "learned network without the rule"}
JOINTS = {3: "left hip", 4: "left knee"}


def _label(name: str) -> str:
    return LABELS.get(name, name)


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def tracking_figure(tracking: dict, path: Path) -> Path:
    """Filtered hip speed of each controller against the commanded speed (paper: change_vel)."""
    fig, ax = plt.subplots(figsize=(8, 3.6))
    desired_drawn = False
    for name, result in tracking.items():
        series = result["series"]
        if not desired_drawn:
            ax.plot(series["time_s"], series["desired_speed_mps"], "k--", lw=1.2, label="commanded")
            desired_drawn = True
        ax.plot(series["time_s"], series["filtered_speed_mps"], color=COLORS.get(name), lw=1.4, label=_label(name))
        end = result["fall_time"] if result["fell"] else result["stall_time"]
        if end is not None:
            ax.axvline(end, color=COLORS.get(name), ls=":", lw=1)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("hip speed, filtered (m/s)")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    return _save(fig, path)


def limit_cycle_figure(walks: dict[float, WalkResult], title: str, path: Path, settle_after: float = 5.0) -> Path:
    """Phase portraits (angle vs rate) of the left hip and knee at each speed: the
    transient after the perturbation in grey, the last ``settle_after`` s in colour
    (paper: limit_cycle)."""
    speeds = sorted(walks)
    fig, axes = plt.subplots(len(speeds), len(JOINTS), figsize=(7, 2.6 * len(speeds)), squeeze=False)
    for row, speed in enumerate(speeds):
        walk = walks[speed]
        late = walk.times >= walk.duration - settle_after
        for col, (index, joint) in enumerate(JOINTS.items()):
            ax = axes[row][col]
            ax.plot(walk.qpos[:, index], walk.qvel[:, index], color="0.75", lw=0.6, label="transient")
            ax.plot(walk.qpos[late, index], walk.qvel[late, index], color="tab:red", lw=1.0,
                    label=f"last {settle_after:.0f} s")
            ax.set_title(f"{joint}, {speed:.1f} m/s", fontsize=9)
            ax.set_xlabel("angle (rad)", fontsize=8)
            ax.set_ylabel("rate (rad/s)", fontsize=8)
            ax.tick_params(labelsize=7)
    axes[0][0].legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    return _save(fig, path)


def convergence_figure(cycles: dict[str, dict[str, dict]], path: Path) -> Path:
    """Per step, the post-touchdown state's distance from the final cycle (log scale)."""
    fig, ax = plt.subplots(figsize=(6, 3.4))
    styles = ["-", "--", ":", "-."]
    for name, by_speed in cycles.items():
        for k, (speed, result) in enumerate(sorted(by_speed.items())):
            if result["distances"]:
                ax.semilogy(result["distances"], styles[k % len(styles)], color=COLORS.get(name), lw=1.2,
                            label=f"{_label(name)} {float(speed):.1f} m/s")
    ax.set_xlabel("step")
    ax.set_ylabel("distance from the final cycle")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    return _save(fig, path)


def poincare_figure(poincare: dict[str, dict[str, dict]], path: Path) -> Path:
    """Eigenvalue magnitudes of the return map's Jacobian per controller and speed."""
    fig, ax = plt.subplots(figsize=(6, 3.4))
    offsets = np.linspace(-0.02, 0.02, max(len(poincare), 1))
    for offset, (name, by_speed) in zip(offsets, poincare.items()):
        first = True
        for speed, result in sorted(by_speed.items()):
            magnitudes = result.get("magnitudes")
            if not magnitudes:
                continue
            ax.scatter(np.full(len(magnitudes), float(speed) + offset), magnitudes, s=14, color=COLORS.get(name),
                       label=_label(name) if first else None)
            first = False
    ax.axhline(1.0, color="k", lw=1, ls="--")
    ax.set_xlabel("commanded speed (m/s)")
    ax.set_ylabel("|eigenvalue| of DP(x*)")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, path)


def push_figure(push: dict, path: Path) -> Path:
    """Filtered speed of each controller in each push scenario (paper Figs. 5-7)."""
    scenarios = push["scenarios"]
    fig, axes = plt.subplots(len(scenarios), 1, figsize=(8, 2.4 * len(scenarios)), squeeze=False, sharex=True)
    falls = {row["scenario"]: row for row in push["table"]}
    for ax, scenario in zip(axes[:, 0], scenarios):
        for t in scenario["times_s"]:
            ax.axvspan(t, t + scenario["duration_s"], color="0.85")
        for name, by_scenario in push["series"].items():
            series = by_scenario[scenario["name"]]
            outcome = falls[scenario["name"]][name]
            end = outcome["fall_time"] if outcome["fell"] else outcome["stall_time"]
            label = _label(name) + (f" ({outcome['outcome']} at {end:.1f} s)" if end is not None else "")
            ax.plot(series["time_s"], series["filtered_speed_mps"], color=COLORS.get(name), lw=1.3, label=label)
        ax.axhline(push["speed"], color="k", ls="--", lw=1)
        ax.set_title(f"{scenario['name'].replace('_', ' ')}: {scenario['force_x_N']:+.0f} N for "
                     f"{scenario['duration_s']:.2f} s ({scenario['impulse_Ns']:+.1f} N s)", fontsize=9)
        ax.set_ylabel("speed (m/s)", fontsize=8)
        ax.legend(fontsize=7, loc="lower left")
        ax.grid(alpha=0.3)
    axes[-1][0].set_xlabel("time (s)")
    return _save(fig, path)


def sweep_figure(sweep: dict[str, dict[str, dict]], path: Path) -> Path:
    """Fraction of push phases survived against impulse, forward and backward."""
    fig, axes = plt.subplots(1, 2, figsize=(8, 3.2), sharey=True)
    for ax, direction in zip(axes, ("backward", "forward")):
        for name, by_direction in sweep.items():
            result = by_direction[direction]
            ax.plot(result["impulses"], result["survived_fraction"], "o-", ms=3, color=COLORS.get(name),
                    label=f"{_label(name)} (all survived up to {result['largest_survived_Ns']:.0f} N s)")
        ax.set_title(f"{direction} pushes", fontsize=9)
        ax.set_xlabel("impulse (N s)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower left")
    axes[0].set_ylabel("fraction of push times survived")
    return _save(fig, path)


def transitions_figure(robustness: dict[str, dict], path: Path) -> Path:
    """The ordered speed-change matrix per controller: green = passed at every phase,
    orange = slow or never reached, red = fell or stalled at some phase."""
    names = list(robustness)
    fig, axes = plt.subplots(1, len(names), figsize=(4.2 * len(names), 4.0), squeeze=False)
    for ax, name in zip(axes[0], names):
        pairs = robustness[name]["transitions"]["pairs"]
        speeds = sorted({p["from"] for p in pairs} | {p["to"] for p in pairs})
        index = {v: i for i, v in enumerate(speeds)}
        grid = np.full((len(speeds), len(speeds), 3), 0.9)
        for p in pairs:
            colour = (0.2, 0.7, 0.3) if p["passed"] else (0.85, 0.2, 0.2) if p["fell_or_stalled"] else (0.95, 0.6, 0.1)
            grid[index[p["from"]], index[p["to"]]] = colour
        ax.imshow(grid, origin="lower")
        ax.set_xticks(range(len(speeds)), [f"{v:.1f}" for v in speeds], fontsize=7)
        ax.set_yticks(range(len(speeds)), [f"{v:.1f}" for v in speeds], fontsize=7)
        ax.set_xlabel("to (m/s)")
        ax.set_ylabel("from (m/s)")
        result = robustness[name]["transitions"]
        ax.set_title(f"{_label(name)}: {result['passed']}/{result['total']} passed", fontsize=9)
    return _save(fig, path)



def margins_figure(robustness: dict[str, dict], path: Path) -> Path:
    """Push margins (the largest impulse survived at every phase, N s) per speed, backward and
    forward, one bar per controller."""
    names = list(robustness)
    fig, axes = plt.subplots(1, 2, figsize=(8, 3.2), sharey=True)
    for ax, direction in zip(axes, ("backward", "forward")):
        speeds = [m["speed"] for m in robustness[names[0]]["push_margins"] if m["direction"] == direction]
        width = 0.8 / len(names)
        for k, name in enumerate(names):
            margins = {m["speed"]: m["largest_survived_Ns"] for m in robustness[name]["push_margins"]
                       if m["direction"] == direction}
            x = np.arange(len(speeds)) + (k - (len(names) - 1) / 2) * width
            bars = ax.bar(x, [margins[v] for v in speeds], width, color=COLORS.get(name), label=_label(name))
            ax.bar_label(bars, fontsize=7)
        ax.set_xticks(range(len(speeds)), [f"{v:.1f} m/s" for v in speeds])
        ax.set_title(f"{direction} pushes", fontsize=9)
        ax.grid(alpha=0.3, axis="y")
    axes[0].set_ylabel("margin (N s, every phase)")
    axes[0].legend(fontsize=7, loc="upper left")
    return _save(fig, path)


def survival_figure(robustness: dict[str, dict], path: Path) -> Path:
    """Survival rate against impulse, backward and forward, per controller, with the 95 %
    Wilson band; the dotted line is 90 %."""
    names = list(robustness)
    fig, axes = plt.subplots(1, 2, figsize=(8, 3.4), sharey=True)
    for ax, direction in zip(axes, ("backward", "forward")):
        for name in names:
            curve = next(c for c in robustness[name]["survival"] if c["direction"] == direction)
            x = curve["impulses_Ns"]
            ax.plot(x, [r["rate"] for r in curve["rates"]], marker="o", ms=3, color=COLORS.get(name),
                    label=_label(name))
            ax.fill_between(x, [r["ci95"][0] for r in curve["rates"]], [r["ci95"][1] for r in curve["rates"]],
                            color=COLORS.get(name), alpha=0.15)
        ax.axhline(0.9, color="grey", ls=":", lw=1)
        ax.set_xlabel("impulse (N s, one 0.1 s push)")
        ax.set_title(f"{direction} pushes (every phase, {len(curve['speeds'])} speeds "
                     f"{min(curve['speeds']):g}-{max(curve['speeds']):g} m/s)", fontsize=9)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("survived (rate, 95 % band)")
    axes[0].legend(fontsize=7, loc="lower left")
    return _save(fig, path)


def model_cases_figure(robustness: dict[str, dict], path: Path) -> Path:
    """The model-error cases per controller: green = walked (the speed error in the cell, m/s),
    orange = stalled, red = fell."""
    names = list(robustness)
    rows = robustness[names[0]]["model_errors"]["rows"]
    columns = [(r["case"], r["speed"]) for r in rows]
    colours = {"walked": (0.2, 0.7, 0.3), "stalled": (0.95, 0.6, 0.1), "fell": (0.85, 0.2, 0.2)}
    fig, ax = plt.subplots(figsize=(max(6.0, 0.32 * len(columns)), 0.6 * len(names) + 1.9))
    grid = np.zeros((len(names), len(columns), 3))
    for i, name in enumerate(names):
        cells = {(r["case"], r["speed"]): r for r in robustness[name]["model_errors"]["rows"]}
        for j, column in enumerate(columns):
            cell = cells[column]
            grid[i, j] = colours.get(cell["outcome"], colours["walked"] if cell["error"] is not None else (0.6,) * 3)
            if cell["error"] is not None:
                ax.text(j, i, f"{cell['error']:+.2f}", ha="center", va="center", fontsize=5, rotation=90)
    ax.imshow(grid, aspect="auto")
    walked = {n: sum(r["error"] is not None for r in robustness[n]["model_errors"]["rows"]) for n in names}
    ax.set_yticks(range(len(names)), [f"{n}: {walked[n]}/{len(columns)}" for n in names], fontsize=8)
    ax.set_title("model errors: walked (green, the speed error m/s), stalled (orange), fell (red)", fontsize=9)
    ax.set_xticks(range(len(columns)), [f"{case} {speed:.1f}" for case, speed in columns], fontsize=6, rotation=90)
    return _save(fig, path)
