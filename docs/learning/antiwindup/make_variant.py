# The shipped network with its speed integral held outside an error band (band, m/s), integrating the error
# clipped (clip, m/s), or, for T s after each command change, integrating only a steady error (steady, s: the
# default SteadyGate otherwise) (MemoryConfig), written as a checkpoint of its own for scripts/compare_policies.py:
#   .venv/bin/python docs/learning/antiwindup/make_variant.py band 0.1 runs/antiwindup/band_0.1.pt
#   .venv/bin/python docs/learning/antiwindup/make_variant.py clip 0.05 runs/antiwindup/clip_0.05.pt
#   .venv/bin/python docs/learning/antiwindup/make_variant.py steady 5 runs/antiwindup/steady_5.pt
import sys
from dataclasses import asdict
from pathlib import Path

from rabbit_policy.runtime.network import PolicyCheckpoint
from rabbit_policy.runtime.policies import packaged_policy_file
from rabbit_policy.runtime.speed_integral import SteadyGate

kind, value, out = sys.argv[1], float(sys.argv[2]), Path(sys.argv[3])
assert kind in ("band", "clip", "steady"), kind
checkpoint = PolicyCheckpoint.load(packaged_policy_file())
if kind == "steady":
    checkpoint.info["memory"]["steady_gate"] = asdict(SteadyGate(seconds=value))
else:
    checkpoint.info["memory"][kind] = value
out.parent.mkdir(parents=True, exist_ok=True)
checkpoint.save(out)
print(out)
