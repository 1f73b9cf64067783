"""Write the URDF of RABBIT generated from the MuJoCo model (``rabbit_sim.urdf``).

    scripts/generate_urdf.py                      # regenerate the packaged file (the paper model)
    scripts/generate_urdf.py --variant drives --torso-mass-scale 1.15 --out rabbit_heavy.urdf
    scripts/generate_urdf.py --check              # exit 1 if the packaged file is out of date
"""

from __future__ import annotations

import sys
from pathlib import Path

from rabbit_msgs_py.cli import ArgumentParser, positive


def main(argv: list[str] | None = None) -> int:
    from rabbit_sim.physics.model import MODEL_VARIANTS, ModelOptions, load_model
    from rabbit_sim.urdf import PACKAGED_URDF, urdf_from_model

    parser = ArgumentParser(description=__doc__)
    parser.add_argument("--variant", choices=MODEL_VARIANTS, default="paper", help="the model variant")
    parser.add_argument("--torso-mass-scale", type=positive, default=1.0, help="factor on the torso mass and inertia")
    parser.add_argument("--out", type=Path, default=PACKAGED_URDF, help="the file to write (default: the packaged one)")
    parser.add_argument("--check", action="store_true", help="compare with --out instead of writing it")
    args = parser.parse_args(argv)
    try:
        text = urdf_from_model(load_model(ModelOptions(args.variant, torso_mass_scale=args.torso_mass_scale)))
    except ValueError as exc:
        parser.error(str(exc))
    if args.check:
        current = args.out.read_text() if args.out.is_file() else None
        if current != text:
            print(f"{args.out} is out of date: run scripts/generate_urdf.py", file=sys.stderr)
            return 1
        print(f"{args.out} is current")
        return 0
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
