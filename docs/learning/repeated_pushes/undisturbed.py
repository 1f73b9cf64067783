# Undisturbed 30 s walks per speed, mean speed 10-30 s and the steps the memory left out, per memory variant
# (memory_probe.py MODE LEVEL): .venv/bin/python docs/learning/repeated_pushes/undisturbed.py skip 0.5 >> undisturbed.txt
# undisturbed.txt: base (08abeef), skip at any weight, skip at 0.5; at 0.9 only the learned walk at 0.8 m/s left 3 steps out (0.7979 m/s).
import sys
sys.argv = ["x"] + sys.argv[1:]
sys.path.insert(0, __file__.rsplit("/", 1)[0])
import memory_probe as mp
from rabbit_policy.runtime import recovery as R
drops = {"n": 0}
if mp.MODE == "skip":
    _obs = R.StepMemory.observe
    def observe(self, tau, v, c):
        from rabbit_policy.runtime.body import touched_down
        if touched_down(self._last_tau, tau) and self.acted:
            drops["n"] += 1
        return _obs(self, tau, v, c)
    R.StepMemory.observe = observe
from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.policies import make_policy
for kind in ("learned", "recovery"):
    for v in (0.7, 0.8, 0.9, 1.0, 1.1, 1.2, 1.3, 1.4, 1.5):
        drops["n"] = 0
        r = walk(make_policy(kind), Scenario.constant(v), 30.0)
        print(mp.MODE, kind, v, "failed" if r.failed else "ok", f"mean10-30 {r.mean_speed(10.0):.4f}", "dropped", drops["n"], flush=True)
