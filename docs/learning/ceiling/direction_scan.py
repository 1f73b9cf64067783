# Which single direction of the at-once residual rescues pushes? (docs/learning.md, "Push recovery:
# the ceiling of each action family and a model-based baseline")
#   .venv/bin/python docs/learning/ceiling/direction_scan.py > docs/learning/ceiling/direction_scan.json
# Classic HZD at 0.7, 1.0 and 1.3 m/s is pushed backward at check 4's 8 phases with 1.5x classic's
# margin there (8, 14, 21 N s); from the push on, one constant offset (rad) is added to Bezier rows
# 1-4 of one output (rows 0 and 5, the step's start and end postures, stay: the impact equalities
# hold), applied at once (family b's settings) for 1 s, then classic alone. Count of the 24 pushes
# survived (5 s after the push, the margin's rule). The offsets that helped became the recovery
# controller's structure (rabbit_policy.runtime.recovery), its constants then tuned on a push grid.
import json

import numpy as np

from rabbit_policy.evaluation.ceiling import FAMILIES, CeilingConfig, prepare, rollout
from rabbit_policy.evaluation.robustness import phase_times
from rabbit_policy.runtime.policies import make_policy

OUTPUTS = ("stance_hip", "stance_knee", "swing_hip", "swing_knee")
MARGINS = ((0.7, 5), (1.0, 9), (1.3, 14))


def main() -> None:
    config = CeilingConfig()
    classic = make_policy("classic")
    phases = [i / 8 for i in range(8)]
    cases = []
    for speed, margin in MARGINS:
        for time in phase_times(classic, speed, config.settle, phases):
            cases.append(prepare(speed, -float(np.ceil(1.5 * margin)), config, time))
    family = FAMILIES["b_at_once"]

    def survived(offsets: dict[str, float]) -> int:
        vector = np.zeros(family.dims)
        for name, value in offsets.items():
            for row in range(1, 5):
                vector[4 * row + OUTPUTS.index(name)] = value
        params = np.tile(vector, (config.blocks, 1))
        return sum(rollout(case, family, params, config)["survived"] for case in cases)

    rows = [{"offsets": {}, "survived": survived({})}]
    for name in OUTPUTS:
        for value in (-0.1, -0.05, 0.05, 0.1):
            rows.append({"offsets": {name: value}, "survived": survived({name: value})})
    for combo in ({"stance_knee": 0.15}, {"stance_knee": 0.2}, {"stance_knee": 0.3},
                  {"stance_knee": 0.1, "swing_knee": -0.1}, {"stance_knee": 0.1, "stance_hip": -0.05},
                  {"stance_knee": 0.1, "swing_hip": 0.1}, {"swing_hip": 0.1, "swing_knee": -0.1}):
        rows.append({"offsets": combo, "survived": survived(combo)})
    print(json.dumps({"cases": len(cases), "impulses_Ns": [float(np.ceil(1.5 * m)) for _, m in MARGINS],
                      "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
