# Which single direction of the at-once residual rescues FORWARD pushes? (docs/learning.md,
# "2026-11-28 (second)"). The backward scan's twin (docs/learning/ceiling/direction_scan.py):
#   .venv/bin/python docs/learning/forward_rule/direction_scan.py > docs/learning/forward_rule/direction_scan.json
# Classic HZD at 0.7, 1.0 and 1.3 m/s is pushed forward at check 4's 8 phases with 1.2x classic's
# forward margin there (25, 16, 11 N s -> 30, 20, 14); from the push on, one constant offset (rad)
# is added to Bezier rows 1-4 of one output (rows 0 and 5 stay: the impact equalities hold),
# applied at once (family b's settings) for 1 s, then classic alone. Count of the 24 pushes
# survived (5 s after the push, the margin's rule), and how the unhelped ones fail.
import json
import sys
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from rabbit_policy.evaluation.ceiling import FAMILIES, CeilingConfig, prepare, rollout
from rabbit_policy.evaluation.robustness import phase_times
from rabbit_policy.runtime.policies import make_policy

OUTPUTS = ("stance_hip", "stance_knee", "swing_hip", "swing_knee")
MARGINS = ((0.7, 25), (1.0, 16), (1.3, 11))
FACTOR = float(sys.argv[1]) if len(sys.argv) > 1 else 1.2


def cases():
    config = CeilingConfig()
    classic = make_policy("classic")
    phases = [i / 8 for i in range(8)]
    out = []
    for speed, margin in MARGINS:
        for time in phase_times(classic, speed, config.settle, phases):
            out.append((speed, float(np.ceil(FACTOR * margin)), time))
    return out


def survived(offsets: dict) -> int:
    config = CeilingConfig()
    family = FAMILIES["b_at_once"]
    vector = np.zeros(family.dims)
    for name, value in offsets.items():
        for row in range(1, 5):
            vector[4 * row + OUTPUTS.index(name)] = value
    params = np.tile(vector, (config.blocks, 1)) if offsets else None
    count = 0
    for speed, impulse, time in cases():
        case = prepare(speed, impulse, config, time)
        count += rollout(case, family, params, config)["survived"]
    return count


def main() -> None:
    combos = [{}]
    for name in OUTPUTS:
        for value in (-0.1, -0.05, 0.05, 0.1):
            combos.append({name: value})
    with ProcessPoolExecutor(2) as pool:
        counts = list(pool.map(survived, combos))
    rows = [{"offsets": c, "survived": n} for c, n in zip(combos, counts)]
    print(json.dumps({"cases": len(cases()), "factor": FACTOR,
                      "impulses_Ns": [float(np.ceil(FACTOR * m)) for _, m in MARGINS], "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
