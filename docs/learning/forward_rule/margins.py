# Forward push margins (check 4's rule: every phase) of the recovery controller with and without
# the forward twin at its best found (rule_probe.ForwardRule, swing knee -0.1 rad):
#   .venv/bin/python docs/learning/forward_rule/margins.py > docs/learning/forward_rule/margins.txt
import sys
from concurrent.futures import ProcessPoolExecutor

sys.path.insert(0, __file__.rsplit("/", 1)[0])
import rule_probe as rp  # noqa: E402

from rabbit_policy.evaluation.robustness import RobustnessConfig, push_margin  # noqa: E402

with ProcessPoolExecutor(2) as pool:
    for name, offsets in (("recovery", (0, 0, 0, 0)), ("recovery + forward twin", (0, 0, 0, -0.1))):
        policy = rp.ForwardRule(offsets)
        row = [push_margin(policy, s, +1, RobustnessConfig(), pool.map)["largest_survived_Ns"] for s in (0.7, 1.0, 1.3)]
        print(name, "forward 0.7 · 1.0 · 1.3:", row, flush=True)
