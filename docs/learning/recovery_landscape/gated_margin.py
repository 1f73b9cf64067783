# With the residual gated, is the margin smooth in the parameters? (docs/learning.md, 2026-11-27 (third))
#   .venv/bin/python docs/learning/recovery_landscape/gated_margin.py > docs/learning/recovery_landscape/gated_margin.json
# margin.py's measurement on the shipped gated residual base (config/train/recovery_gated_es.yaml:
# residual_base recovery_gated, the env scales the residual by the recovery rule's weight): the same 24
# episodes (landscape.py's draw), the zero residual and 8 perturbations per sigma. Per episode: failed or
# not, and the margin, the lowest hip velocity (m/s, world x) at the end of each env step in the 1.5 s
# after the push starts. Ungated the margin moved by ~0.03 m/s at every sigma (the trajectory moved
# before the push); if gating makes it move in proportion to sigma, a margin term in the reward is a
# smooth training signal where the fall penalty is not.
import json

from margin import study

SIGMAS = (0.001, 0.003, 0.01, 0.03, 0.1)

if __name__ == "__main__":
    print(json.dumps(study("recovery_gated_es.yaml", SIGMAS), indent=1))
