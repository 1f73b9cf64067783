# Is there a smooth margin to learn from? (docs/learning.md, 2026-11-27 (later))
#   .venv/bin/python docs/learning/recovery_landscape/margin.py > docs/learning/recovery_landscape/margin.json
# landscape.py's 24 episodes (the recovery preset, drawn once) for the zero residual and 8 perturbations per
# sigma. Per episode: failed or not, and the *margin*: the lowest hip velocity (m/s, world x) sampled at
# the end of each env step (20 ms) in the 1.5 s after the push starts (negative: the hip rolled back).
# For the episodes that do not flip, how far the margin moves from the zero residual's, per sigma: a
# quantity that moves in proportion to sigma is smooth in the parameters, one that jumps is not.
import json
import sys

import numpy as np

from landscape import setup


def margin_rollout(env, forward, episode) -> tuple[bool, float]:
    seed, first, second = episode
    obs, _ = env.reset(seed=seed, options={"desired_speed": first, "next_speed": second})
    lowest = np.inf
    while True:
        obs, _r, terminated, truncated, info = env.step(env.bounds.to_normalised(forward(obs)))
        loop = env.loop
        if loop.placed_pushes:
            start = loop.placed_pushes[0].time
            if start <= info["time"] <= start + 1.5:
                lowest = min(lowest, float(loop.data.qvel[0]))
        if terminated or truncated:
            return bool(terminated), lowest


def study(preset: str = "recovery_residual_es.yaml", sigmas: tuple[float, ...] = (0.001, 0.003, 0.01, 0.03)) -> dict:
    """The centre's and 8 members' outcomes and margins per sigma on ``preset``'s env (gated_margin.py
    runs it on the gated preset)."""
    from rabbit_policy.learning.env import RabbitHZDEnv
    from rabbit_policy.learning.es import set_flat
    from rabbit_policy.runtime.network import NetworkForward

    config, net, theta, episodes, rng = setup(preset)
    env = RabbitHZDEnv(**config.env_kwargs())

    def run(params: np.ndarray) -> list[tuple[bool, float]]:
        set_flat(net, params)
        forward = NetworkForward.of(net)
        return [margin_rollout(env, forward, e) for e in episodes]

    centre = run(theta)
    out = {"centre": [{"failed": f, "margin": m} for f, m in centre], "sigmas": []}
    for sigma in sigmas:
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
    return out


if __name__ == "__main__":
    print(json.dumps(study(), indent=1))
