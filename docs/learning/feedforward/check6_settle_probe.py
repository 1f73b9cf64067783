# Check 6's return map at one speed, linearised after 30-70 settle steps instead of 40 (150 samples, one seed).
#   .venv/bin/python docs/learning/feedforward/check6_settle_probe.py POLICY.pt|classic 1.3 30 40 50 60 70
import sys, time
from rabbit_policy.evaluation import stability as st
from rabbit_policy.runtime.policies import LearnedPolicy
path, speed = sys.argv[1], float(sys.argv[2])
orig = st.WalkReturnMap.__init__
for settle in [int(a) for a in sys.argv[3:]]:
    def init(self, *a, settle=settle, **k):
        k["settle_steps"] = settle
        return orig(self, *a, **k)
    st.WalkReturnMap.__init__ = init
    t = time.time()
    from rabbit_policy.runtime.policies import make_policy
    pol = make_policy("classic") if path == "classic" else LearnedPolicy(path)
    r = st.analyse_stability(pol, speed, True, samples=150)
    print(path.split('/')[-1], speed, "settle", settle, "largest", round(float(r.analysis.magnitudes.max()), 3), f"{time.time()-t:.0f}s", flush=True)
