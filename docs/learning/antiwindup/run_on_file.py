# Run one of docs/learning's probe scripts with a policy file in place of a controller name:
#   .venv/bin/python docs/learning/antiwindup/run_on_file.py docs/learning/speed_change_probe/three_segments.py runs/antiwindup/band_0.1.pt
# (the scripts call make_policy(name); a name ending in .pt is loaded as that checkpoint instead).
import runpy
import sys

import rabbit_policy.runtime.policies as policies

_make_policy = policies.make_policy
policies.make_policy = lambda name, *a, **k: policies.LearnedPolicy(name) if str(name).endswith(".pt") else _make_policy(name, *a, **k)
script, *names = sys.argv[1:]
sys.argv = [script, *names]
runpy.run_path(script, run_name="__main__")
