# settling.py's measure on a policy file (docs/learning.md, 2026-11-27 (seventh)); prints the summary, the rows on stderr.
#   .venv/bin/python docs/learning/feedforward/settling_file.py POLICY.pt [SEED (38)] > summary.txt 2> rows.json
import sys, json
sys.path.insert(0, "docs/learning/settling")
import settling
from rabbit_policy.runtime.policies import LearnedPolicy
settling.make_policy = lambda name: LearnedPolicy(sys.argv[1])
r = settling.measure("learned", 200, int(sys.argv[2]) if len(sys.argv) > 2 else 38)
print(json.dumps({k: v for k, v in r.items() if not isinstance(v, list)}))
print(json.dumps(r), file=sys.stderr)
