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

from landscape import training_config


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
    from rabbit_policy.learning.es import get_flat, set_flat, stratified_episodes
    from rabbit_policy.learning.warm_start import zero_residual_network
    from rabbit_policy.runtime.actions import policy_bounds
    from rabbit_policy.runtime.gait_library import GaitLibrary
    from rabbit_policy.runtime.memory import INPUTS
    from rabbit_policy.runtime.network import NetworkForward

    config = training_config().trainer
    bounds = policy_bounds("residual", GaitLibrary.load())
    net = zero_residual_network(bounds.low, bounds.high, INPUTS[config.features], 0)
    theta = get_flat(net)
    env = RabbitHZDEnv(**config.env_kwargs())
    rng = np.random.default_rng(0)
    episodes = stratified_episodes(rng, config.episodes, (0.7, 1.5))

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
