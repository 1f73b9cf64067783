# Checks 2 and 3 and the tracking schedule for policy files, on this machine (docs/learning.md, 2026-11-27
# (seventh)): the speed-change figures of checks 1-6 move between machines, so candidates are compared in one run.
#   .venv/bin/python docs/learning/feedforward/changes_checks.py POLICY.pt ... > changes_checks.jsonl
import json
import sys
from multiprocessing import get_context

from rabbit_policy.evaluation.acceptance import Criteria, acceptance
from rabbit_policy.evaluation.robustness import RobustnessConfig, random_sequences, transitions
from rabbit_policy.runtime.policies import LearnedPolicy

with get_context("fork").Pool(2) as pool:
    for path in sys.argv[1:]:
        policy = LearnedPolicy(path)
        config = RobustnessConfig()
        changes, sequences = transitions(policy, config, pool.map), random_sequences(policy, config, pool.map)
        schedule = acceptance(policy, Criteria(), speeds=(), map_fn=pool.map)["schedule"]
        print(json.dumps({"policy": path, "transitions": [changes["passed"], changes["total"], changes["fell_or_stalled"]],
                          "random_sequences": {k: v for k, v in sequences.items() if not isinstance(v, list)},
                          "schedule": {k: v for k, v in schedule.items() if not isinstance(v, (list, dict))},
                          "schedule_reach": [s.get("reach_time") for s in schedule.get("segments", [])]}), flush=True)
