"""Is there a training signal above the noise? The measurement made before any ES budget is spent.

From parameters theta, ``pairs`` Gaussian directions eps_i are scored as ES scores them
(mirrored members theta +- sigma eps_i, each on the same episodes), on two independent episode
sets A and B. Per direction the mirrored difference d_i = R(theta + sigma eps_i) - R(theta -
sigma eps_i) (mean return over the set's episodes). If the returns measure the policy, d on A
predicts d on B:

* ``difference_correlation``: Pearson's r between d_A and d_B over the directions (chance:
  about +-2 / sqrt(pairs));
* ``cosine_same_directions``: the cosine between the rank-based ES gradient estimates of A and
  of B (same directions, independent episodes: the episodes' noise);
* ``cosine_fresh_directions``: the cosine between A's estimate and one from fresh directions on
  fresh episodes (what two successive generations from theta would see);
* ``return_spread``: the std of the member returns on A, and ``difference_spread`` that of d_A.

Every evaluation is :func:`rabbit_policy.learning.es._evaluate` (the deployed loop of the spec,
the episodes :func:`~rabbit_policy.learning.es.stratified_episodes` draws), so the probe measures
exactly what a generation of training sees.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rabbit_policy.learning.es import EnvKey, Episode, _evaluate, centred_ranks, stratified_episodes
from rabbit_policy.runtime.fixed_order import vecmat


@dataclass(frozen=True)
class Scored:
    """The mean return (over one episode set) of each member theta + sigma eps_i and theta - sigma eps_i."""

    plus: np.ndarray
    minus: np.ndarray

    @property
    def differences(self) -> np.ndarray:
        return self.plus - self.minus


def score(map_fn, key: EnvKey, theta: np.ndarray, eps: np.ndarray, sigma: float,
          episodes: list[Episode]) -> Scored:
    """Every mirrored member of ``eps`` (pairs x parameters) scored on ``episodes``."""
    members = [theta + sigma * e for e in eps] + [theta - sigma * e for e in eps]
    results = map_fn(_evaluate, [(key, m, episodes) for m in members])
    returns = np.array([np.mean([r.total for r in member]) for member in results])
    return Scored(returns[: len(eps)], returns[len(eps):])


def rank_gradient(scored: Scored, eps: np.ndarray, sigma: float) -> np.ndarray:
    """The ES gradient estimate from centred ranks (:class:`~rabbit_policy.learning.es.EvolutionStrategy`'s, no decay)."""
    ranks = centred_ranks(np.concatenate([scored.plus, scored.minus]))
    pairs = len(eps)
    return vecmat(ranks[:pairs] - ranks[pairs:], eps) / (2 * pairs * sigma)


def cosine(a: np.ndarray, b: np.ndarray) -> float:
    na, nb = float(np.sqrt(a @ a)), float(np.sqrt(b @ b))
    return float(a @ b / (na * nb)) if na > 0 and nb > 0 else float("nan")


def correlation(a: np.ndarray, b: np.ndarray) -> float:
    """Pearson's r (NaN when either is constant)."""
    a, b = a - a.mean(), b - b.mean()
    return cosine(a, b)


def probe(map_fn, key: EnvKey, theta: np.ndarray, sigma: float, pairs: int, episodes: int,
          seed: int) -> dict[str, float]:
    """The measurement of the module docstring at ``sigma`` (its draws from ``seed``)."""
    rng = np.random.default_rng(seed)
    eps = rng.standard_normal((pairs, theta.size))
    set_a = stratified_episodes(rng, episodes, (0.7, 1.5))
    set_b = stratified_episodes(rng, episodes, (0.7, 1.5))
    a = score(map_fn, key, theta, eps, sigma, set_a)
    b = score(map_fn, key, theta, eps, sigma, set_b)
    fresh_eps = rng.standard_normal((pairs, theta.size))
    fresh = score(map_fn, key, theta, fresh_eps, sigma, stratified_episodes(rng, episodes, (0.7, 1.5)))
    grad_a = rank_gradient(a, eps, sigma)
    return {
        "sigma": sigma, "pairs": pairs, "episodes": episodes, "seed": seed,
        "difference_correlation": round(correlation(a.differences, b.differences), 3),
        "chance_level": round(2.0 / np.sqrt(pairs), 3),
        "cosine_same_directions": round(cosine(grad_a, rank_gradient(b, eps, sigma)), 3),
        "cosine_fresh_directions": round(cosine(grad_a, rank_gradient(fresh, fresh_eps, sigma)), 3),
        "return_spread": round(float(np.std(np.concatenate([a.plus, a.minus]))), 3),
        "difference_spread": round(float(np.std(a.differences)), 3),
        "mean_return": round(float(np.mean(np.concatenate([a.plus, a.minus]))), 3),
    }
