# (docs/learning.md, 2026-11-27 (seventh); variants.txt)
#   .venv/bin/python docs/learning/feedforward/variant_anchor_at_change_probe.py POLICY.pt on|off 60 37 rs
"""Probe: a change during a decay also moves the anchor by the feed-forward's shift."""
import sys, json
sys.path.insert(0, "docs/learning/settling")
import settling
from rabbit_policy.runtime.policies import LearnedPolicy
from rabbit_policy.runtime import speed_integral as si
orig = si.SpeedIntegral.update
def upd(self, error, desired_speed):
    previous, decaying, anchor = self._last_command, self._decaying, self._anchor
    value = orig(self, error, desired_speed)
    ff = self.config.feedforward
    if ff is not None and previous is not None and desired_speed != previous and decaying:
        self._anchor = anchor + ff.at(desired_speed) - ff.at(previous)
    return value
if sys.argv[2] == "on": si.SpeedIntegral.update = upd
p = LearnedPolicy(sys.argv[1])
settling.make_policy = lambda name: p
r = settling.measure("learned", int(sys.argv[3]), int(sys.argv[4]))
print(sys.argv[2], json.dumps({k: v for k, v in r.items() if not isinstance(v, list)}), flush=True)
if len(sys.argv) > 5:
    from multiprocessing import get_context
    from rabbit_policy.evaluation.robustness import RobustnessConfig, random_sequences
    seq = random_sequences(p, RobustnessConfig())
    print(sys.argv[2], "random", seq["passed"], flush=True)
