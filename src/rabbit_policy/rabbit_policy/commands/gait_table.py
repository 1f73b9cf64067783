"""Print the classic gait library as a Markdown table (for the README and reports).

    scripts/gait_table.py [--gait-dir DIR]
"""

from __future__ import annotations

from pathlib import Path

from rabbit_msgs_py.cli import ArgumentParser
from rabbit_msgs_py.environment import ensure_localhost_discovery


def main() -> None:
    ensure_localhost_discovery()
    from rabbit_hzd_controller.gait import Gait
    from rabbit_policy.runtime.gait_library import packaged_gait_dir

    from rabbit_policy.experiment.options import add_gait_dir_option

    parser = ArgumentParser(description=__doc__)
    add_gait_dir_option(parser)
    args = parser.parse_args()
    directory = Path(args.gait_dir) if args.gait_dir else packaged_gait_dir()
    print("| design speed (m/s) | step length (m) | step period (s) | Kd (N m s/rad) | cost | "
          "60 s walk: mean speed (m/s) | peak torque (N m) | max friction ratio | passed |")
    print("|---|---|---|---|---|---|---|---|---|")
    for path in sorted(directory.glob("gait_*.json")):
        g = Gait.load(path)
        v = g.info.get("validation", {})
        e = g.info.get("evaluation", {})
        print(f"| {g.speed:.2f} | {g.step_length:.3f} | {g.step_period:.3f} | {g.kd:.1f} | {g.cost:.3f} | "
              f"{v.get('mean_speed', float('nan')):.3f} | {v.get('peak_torque', float('nan')):.1f} | "
              f"{e.get('max_friction_ratio', float('nan')):.2f} | {'yes' if v.get('passed') else 'no'} |")


if __name__ == "__main__":
    main()
