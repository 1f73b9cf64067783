# CMA-ES over the forward twin's offsets, threshold and saturation (rule_probe.py's ForwardRule on
# the recovery controller), on forward pushes at check 4's 8 phases, 0.7/1.0/1.3 m/s, 1.2x and 1.5x
# classic's forward margin (48 cases):
#   .venv/bin/python docs/learning/forward_rule/rule_cma.py > docs/learning/forward_rule/rule_cma.json
import json
import sys
from concurrent.futures import ProcessPoolExecutor

import cma
import numpy as np

sys.path.insert(0, __file__.rsplit("/", 1)[0])
import rule_probe as rp  # noqa: E402

from rabbit_policy.evaluation.robustness import RobustnessConfig, push_survived  # noqa: E402
from rabbit_policy.runtime.policies import make_policy  # noqa: E402

FACTORS = (1.2, 1.5)
base = make_policy("recovery")
CASES = []
for f in FACTORS:
    rp.FACTOR = f
    CASES += rp.cases(base)


def score(x):
    policy = rp.ForwardRule(tuple(x[:4]), max(float(x[4]), 0.0), max(float(x[5]), 0.02))
    config = RobustnessConfig()
    return sum(push_survived((policy, s, t, i, config)) for s, t, i in CASES)


def main():
    x0 = [0.0, 0.0, 0.0, -0.1, 0.05, 0.2]
    es = cma.CMAEvolutionStrategy(x0, 0.08, {"popsize": 12, "seed": 5, "verbose": -9})
    history, best = [], (score(x0), x0)
    print(f"start {best}", file=sys.stderr, flush=True)
    with ProcessPoolExecutor(2) as pool:
        for g in range(int(sys.argv[1]) if len(sys.argv) > 1 else 14):
            xs = es.ask()
            scores = list(pool.map(score, xs))
            es.tell(xs, [-s for s in scores])
            i = int(np.argmax(scores))
            if scores[i] > best[0]:
                best = (scores[i], [round(float(v), 4) for v in xs[i]])
            history.append(scores)
            print(f"gen {g}: {max(scores)} best {best}", file=sys.stderr, flush=True)
    print(json.dumps({"cases": len(CASES), "factors": FACTORS, "best": best[1], "survived": best[0],
                      "history": history}, indent=1))


if __name__ == "__main__":
    main()
