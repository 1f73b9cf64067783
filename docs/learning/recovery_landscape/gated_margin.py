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
import sys

import numpy as np

from landscape import setup
from margin import margin_rollout

SIGMAS = (0.001, 0.003, 0.01, 0.03, 0.1)


def main() -> None:
    from rabbit_policy.learning.env import RabbitHZDEnv
    from rabbit_policy.learning.es import set_flat
    from rabbit_policy.runtime.network import NetworkForward

    config, net, theta, episodes, rng = setup("recovery_gated_es.yaml")
    env = RabbitHZDEnv(**config.env_kwargs())

    def run(params: np.ndarray) -> list[tuple[bool, float]]:
        set_flat(net, params)
        forward = NetworkForward.of(net)
        return [margin_rollout(env, forward, e) for e in episodes]

    centre = run(theta)
    out = {"centre": [{"failed": f, "margin": m} for f, m in centre], "sigmas": []}
    for sigma in SIGMAS:
        moves, flips = [], 0
        for _ in range(8):
            member = run(theta + sigma * rng.standard_normal(theta.size))
            for (f0, m0), (f, m) in zip(centre, member):
                if f != f0:
                    flips += 1
                elif np.isfinite(m0) and np.isfinite(m):
                    moves.append(abs(m - m0))
        moves = np.array(moves)
        row = {"sigma": sigma, "flips": flips, "episodes": 8 * len(episodes),
               "margin_move_median": float(np.median(moves)), "margin_move_p90": float(np.quantile(moves, 0.9)),
               "margin_move_max": float(moves.max()), "share_unmoved": float(np.mean(moves < 1e-9))}
        out["sigmas"].append(row)
        print(row, file=sys.stderr, flush=True)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
