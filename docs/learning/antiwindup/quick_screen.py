# A first look at checkpoints of the run with the band in its loop (config/train/final_gated_band_es.yaml), on what
# the band cost the shipped network (docs/learning.md, 2026-11-27 (fifth)): check 5's model cases (judged ones and
# the probes, RobustnessConfig's cases and speeds, check 5's own walk) and the settling probe's 60 changes.
#   .venv/bin/python docs/learning/antiwindup/quick_screen.py runs/final_gated_band/evaluated/00340.pt ... >> screen.jsonl
# One JSON line per checkpoint. Not checks 1-6: scripts/compare_policies.py judges a candidate.
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "settling"))
from settling import TOLERANCE, draws  # noqa: E402

from rabbit_policy.evaluation.acceptance import BroadCriteria  # noqa: E402
from rabbit_policy.evaluation.robustness import RobustnessConfig, model_errors  # noqa: E402
from rabbit_policy.experiment.loop import walk  # noqa: E402
from rabbit_policy.experiment.scenario import Scenario  # noqa: E402
from rabbit_policy.runtime.policies import LearnedPolicy  # noqa: E402

config, judged = RobustnessConfig(), BroadCriteria().judged_models
for path in sys.argv[1:]:
    policy = LearnedPolicy(path)
    models = model_errors(policy, config)["rows"]
    settled = 0
    for a, b, t in draws(60, 37):
        result = walk(policy, Scenario(schedule=((0.0, a), (t, b))), t + 10.0)
        settled += (not result.failed) and abs(result.mean_speed(t + 5.0, t + 10.0) - b) <= TOLERANCE
    print(json.dumps({"policy": path, "settled_of_60": settled,
                      "judged_models_passed": sum(m["passed"] for m in models if m["case"] in judged),
                      "models": [(m["case"], m["speed"], m["outcome"], m["error"] and round(m["error"], 3))
                                 for m in models]}), flush=True)
