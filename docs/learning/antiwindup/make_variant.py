# The shipped network with its speed integral held outside an error band (band, m/s), integrating the error
# clipped (clip, m/s), or its windup after a command change decaying once the hip has passed the new command (decay,
# s: WindupDecay's seconds, tau its default) (MemoryConfig), written as a checkpoint of its own for
# scripts/compare_policies.py:
#   .venv/bin/python docs/learning/antiwindup/make_variant.py band 0.1 runs/antiwindup/band_0.1.pt
#   .venv/bin/python docs/learning/antiwindup/make_variant.py clip 0.05 runs/antiwindup/clip_0.05.pt
#   .venv/bin/python docs/learning/antiwindup/make_variant.py decay 5 runs/antiwindup/decay_5.pt
import sys
from dataclasses import asdict
from pathlib import Path

from rabbit_policy.runtime.network import PolicyCheckpoint
from rabbit_policy.runtime.policies import packaged_policy_file
from rabbit_policy.runtime.speed_integral import WindupDecay

kind, value, out = sys.argv[1], float(sys.argv[2]), Path(sys.argv[3])
assert kind in ("band", "clip", "decay"), kind
checkpoint = PolicyCheckpoint.load(packaged_policy_file())
if kind == "decay":
    checkpoint.info["memory"]["windup_decay"] = asdict(WindupDecay(seconds=value))
else:
    checkpoint.info["memory"][kind] = value
out.parent.mkdir(parents=True, exist_ok=True)
checkpoint.save(out)
print(out)
