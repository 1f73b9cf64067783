# Does the lottery come from before the push? (docs/learning.md, 2026-11-27 (later))
#   .venv/bin/python docs/learning/recovery_landscape/gated.py > docs/learning/recovery_landscape/gated.json
# landscape.py's 24 episodes and perturbations, with the residual *gated* by the recovery rule: the
# network's normalised action is multiplied by the rule's weight w at the previous decision
# (RecoveryPolicy.last_weight, 0 while the hip keeps its pace, up to 1 at the rule's full deficit).
# Undisturbed, w is 0 and every member walks the recovery controller's trajectory to the tick, so a
# member can only differ from the zero residual after something slowed the hip (the push). Flips per
# sigma as in landscape.py.
import json
import sys

import numpy as np

from landscape import setup


def gated_rollout(env, forward, episode) -> bool:
    seed, first, second = episode
    obs, _ = env.reset(seed=seed, options={"desired_speed": first, "next_speed": second})
    base = env.base
    while True:
        action = env.bounds.to_normalised(forward(obs)) * base.last_weight
        obs, _r, terminated, truncated, _info = env.step(action)
        if terminated or truncated:
            return bool(terminated)


def main() -> None:
    from rabbit_policy.learning.env import RabbitHZDEnv
    from rabbit_policy.learning.es import set_flat
    from rabbit_policy.runtime.network import NetworkForward

    config, net, theta, episodes, rng = setup()
    env = RabbitHZDEnv(**config.env_kwargs())

    def run(params: np.ndarray) -> np.ndarray:
        set_flat(net, params)
        forward = NetworkForward.of(net)
        return np.array([gated_rollout(env, forward, e) for e in episodes])

    centre = run(theta)
    out = {"centre_failed": int(centre.sum()), "episodes": len(episodes), "sigmas": []}
    for sigma in (0.001, 0.01, 0.03, 0.1):
        flips, failed = [], []
        for _ in range(8):
            member = run(theta + sigma * rng.standard_normal(theta.size))
            flips.append(int((member != centre).sum()))
            failed.append(int(member.sum()))
        out["sigmas"].append({"sigma": sigma, "flipped_per_member": flips, "failed_per_member": failed})
        print(out["sigmas"][-1], file=sys.stderr, flush=True)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
