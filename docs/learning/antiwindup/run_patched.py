# Run one of docs/learning's probe scripts with one of probe2.py's rules patched into the shipped network in place
# of a controller name:
#   .venv/bin/python docs/learning/antiwindup/run_patched.py docs/learning/settling/settling.py --changes 200 --seed 38 xdecay:5:0.5
# (the scripts call make_policy(name); a name with a colon is probe2.patched(name) instead).
import runpy
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from probe2 import patched  # noqa: E402

import rabbit_policy.runtime.policies as policies  # noqa: E402

_make_policy = policies.make_policy
policies.make_policy = lambda name, *a, **k: patched(name) if ":" in str(name) else _make_policy(name, *a, **k)
script, *names = sys.argv[1:]
sys.argv = [script, *names]
runpy.run_path(script, run_name="__main__")
