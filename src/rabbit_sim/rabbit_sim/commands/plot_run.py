"""Plot a recorded run (a rosbag2 bag from ``run_stack.py --record`` or ``record.py``).

    scripts/plot_run.py runs/walk1            # writes PNGs into runs/walk1_plots/ (the bag stays a bag)
    scripts/plot_run.py runs/walk1 --out figs --show

Figures (PNG): ``speed.png`` commanded speed vs hip speed filtered over 200 samples, with
the pushes (``/push_applied``) shaded; ``joints.png`` the four joint angles (rad) and torques
(N m); ``limit_cycle.png`` the stance-leg phase portrait — left hip angle vs rate over the
run, closing on the walking limit cycle; ``pitch.png`` torso pitch (rad). Time axis: the
messages' sim-time stamps (s). Reads the bag with ``rosbags`` (AnyReader), the library
the recorder writes with.
Exit status: 0 written, 1 the bag cannot be read or holds no /joint_states.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from rabbit_msgs_py.cli import ArgumentParser


def read_run(bag: Path) -> dict[str, np.ndarray]:
    """Arrays from the bag: t, q (n x 7), dq, effort from /joint_states; tv, v from
    /hip_velocity; tau (n x 4) from /joint_torques; cmd (time by log order) from /cmd_speed;
    push (n x 2: stamp s, force x N; a zero force ends a push) from /push_applied."""
    from rosbags.highlevel import AnyReader

    from rabbit_msgs_py.conversions import stamp_to_seconds
    from rosbags.typesys import Stores, get_typestore

    t, q, dq, eff, tv, v, tau, cmd, push = [], [], [], [], [], [], [], [], []
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        wanted = {"/joint_states", "/hip_velocity", "/joint_torques", "/cmd_speed", "/hzd/alpha", "/push_applied"}
        connections = [c for c in reader.connections if c.topic in wanted]
        last_t = 0.0
        for conn, _log_time, raw in reader.messages(connections=connections):
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic == "/joint_states":
                last_t = stamp_to_seconds(msg.header.stamp)
                t.append(last_t)
                q.append(msg.position)
                dq.append(msg.velocity)
                eff.append(msg.effort)
            elif conn.topic == "/hip_velocity":
                tv.append(stamp_to_seconds(msg.header.stamp))
                v.append(msg.twist.linear.x)
            elif conn.topic == "/joint_torques":
                tau.append(msg.effort)
            elif conn.topic == "/cmd_speed":
                cmd.append((last_t, msg.data))
            elif conn.topic == "/push_applied":
                push.append((stamp_to_seconds(msg.header.stamp), msg.wrench.force.x))
    if not t:
        raise ValueError(f"{bag} holds no /joint_states messages")
    return {
        "t": np.array(t), "q": np.array(q), "dq": np.array(dq), "effort": np.array(eff),
        "tv": np.array(tv), "v": np.array(v), "tau": np.array(tau).reshape(-1, 4),
        "cmd": np.array(cmd).reshape(-1, 2), "push": np.array(push).reshape(-1, 2),
    }


def push_intervals(push: np.ndarray, end: float) -> list[tuple[float, float, float]]:
    """(start s, end s, force x N) of each push from /push_applied rows (stamp, force x);
    a push still acting at the end of the bag ends at ``end``."""
    intervals = []
    for i, (start, force) in enumerate(push):
        if force != 0.0:
            stop = push[i + 1, 0] if i + 1 < len(push) else end
            intervals.append((float(start), float(stop), float(force)))
    return intervals


def moving_average(x: np.ndarray, n: int) -> np.ndarray:
    if len(x) < n:
        return x.copy()
    c = np.cumsum(np.insert(x, 0, 0.0))
    out = np.empty_like(x)
    out[n - 1:] = (c[n:] - c[:-n]) / n
    out[: n - 1] = c[1:n] / np.arange(1, n)
    return out


def plot(run: dict[str, np.ndarray], out: Path, show: bool = False) -> list[Path]:
    import matplotlib

    if not show:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    t, q, dq = run["t"], run["q"], run["dq"]
    names = ("left hip", "left knee", "right hip", "right knee")
    written = []

    fig, ax = plt.subplots(figsize=(9, 4))
    if len(run["v"]):
        ax.plot(run["tv"], run["v"], lw=0.5, alpha=0.4, label="hip speed")
        ax.plot(run["tv"], moving_average(run["v"], 200), lw=1.5, label="hip speed, 200-sample mean")
    if len(run["cmd"]):
        times = np.concatenate([run["cmd"][:, 0], [t[-1]]])
        ax.step(times, np.concatenate([run["cmd"][:, 1], run["cmd"][-1:, 1]]), where="post", color="k",
                label="commanded (/cmd_speed)")
    for k, (start, stop, force) in enumerate(push_intervals(run.get("push", np.empty((0, 2))), float(t[-1]))):
        ax.axvspan(start, stop, color="tab:red", alpha=0.25, label="push (/push_applied)" if k == 0 else None)
        ax.annotate(f"{force:+.0f} N", (start, ax.get_ylim()[1]), fontsize=7, va="top")
    ax.set(xlabel="sim time (s)", ylabel="speed (m/s)", title="Commanded vs filtered hip speed")
    ax.legend(loc="best")
    written.append(_save(fig, out / "speed.png"))

    fig, (a1, a2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for j, name in enumerate(names):
        a1.plot(t, q[:, 3 + j], lw=0.8, label=name)
    a1.set(ylabel="angle (rad)", title="Joint angles and torques")
    a1.legend(loc="upper right", ncol=4, fontsize=8)
    tau = run["tau"] if len(run["tau"]) else run["effort"][:, 3:]
    tt = t[: len(tau)]
    for j, name in enumerate(names):
        a2.plot(tt, tau[: len(tt), j], lw=0.6, label=name)
    a2.set(xlabel="sim time (s)", ylabel="torque (N m)")
    written.append(_save(fig, out / "joints.png"))

    fig, ax = plt.subplots(figsize=(5.5, 5))
    ax.plot(q[:, 3], dq[:, 3], lw=0.5)
    ax.set(xlabel="left hip angle (rad)", ylabel="left hip rate (rad/s)",
           title="Phase portrait (stance and swing), limit cycle")
    written.append(_save(fig, out / "limit_cycle.png"))

    fig, ax = plt.subplots(figsize=(9, 3.5))
    ax.plot(t, q[:, 2], lw=0.8)
    ax.axhline(0.5, color="r", ls="--", lw=0.8)
    ax.axhline(-0.5, color="r", ls="--", lw=0.8, label="fall limit ±0.5 rad")
    ax.set(xlabel="sim time (s)", ylabel="torso pitch (rad)", title="Torso pitch (+ leaning forward)")
    ax.legend(loc="best")
    written.append(_save(fig, out / "pitch.png"))
    if show:
        plt.show()
    plt.close("all")
    return written


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("bag", type=Path, help="bag directory")
    parser.add_argument("--out", type=Path, default=None, help="figure directory (default: BAG_plots beside the bag)")
    parser.add_argument("--show", action="store_true", help="also open the figures")
    args = parser.parse_args(argv)
    try:
        run = read_run(args.bag)
    except Exception as exc:  # rosbags raises several reader errors; all mean "cannot read"
        print(f"error: cannot read {args.bag}: {exc}", file=sys.stderr)
        return 1
    for path in plot(run, args.out or args.bag.parent / f"{args.bag.name}_plots", args.show):
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
