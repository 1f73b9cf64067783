"""The training-signal probe (rabbit_policy.learning.signal, scripts/probe_signal.py): scoring is a
pure function of (parameters, episodes), so a set scored twice correlates perfectly with itself and
the probe's numbers repeat; the statistics are the textbook ones."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rabbit_policy.learning.es import ESConfig, get_flat, stratified_episodes
from rabbit_policy.learning.signal import correlation, cosine, probe, score


ROOT = Path(__file__).resolve().parents[2]


def _serial(fn, items):
    return [fn(item) for item in items]


@pytest.mark.unit
def test_the_statistics_are_pearson_and_cosine():
    a, b = np.array([1.0, 2.0, 3.0]), np.array([2.0, 4.0, 7.0])
    assert correlation(a, b) == pytest.approx(np.corrcoef(a, b)[0, 1])
    assert cosine(a, -a) == pytest.approx(-1.0) and np.isnan(correlation(a, np.ones(3)))


@pytest.mark.sim
def test_a_set_scored_twice_gives_the_same_differences_and_the_probe_repeats():
    from rabbit_policy.learning.spec_env import make_env
    from rabbit_policy.runtime.network import HZDPolicyNet

    config = ESConfig(max_steps=5, distribution="paper", action="residual")
    key = tuple(sorted(config.env_kwargs().items()))
    env = make_env(dict(key))
    net = HZDPolicyNet(env.bounds.low, env.bounds.high, inputs=env.observation_space.shape[0], output="tanh")
    theta = get_flat(net)
    rng = np.random.default_rng(3)
    eps = rng.standard_normal((3, theta.size))
    episodes = stratified_episodes(rng, 2, (0.7, 1.5))
    first, again = (score(_serial, key, theta, eps, 0.2, episodes) for _ in range(2))
    assert np.array_equal(first.differences, again.differences)
    row = probe(_serial, key, theta, 0.2, 3, 2, seed=0)
    assert row == probe(_serial, key, theta, 0.2, 3, 2, seed=0)
    assert -1.0 <= row["difference_correlation"] <= 1.0 and row["chance_level"] == pytest.approx(2 / np.sqrt(3), abs=1e-3)


@pytest.mark.slow
@pytest.mark.sim
def test_probe_signal_prints_one_json_object_for_a_preset(tmp_path):
    out = tmp_path / "probe.json"
    run = subprocess.run([sys.executable, str(ROOT / "scripts" / "probe_signal.py"), "--preset", "tiny", "--pairs", "2",
                          "--episodes", "1", "--sigmas", "0.2", "--workers", "1", "--out", str(out)],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    report = json.loads(run.stdout)
    assert report == json.loads(out.read_text()) and report["probes"][0]["sigma"] == 0.2
    assert report["preset"] == "config/reproduce/tiny.yaml"  # the repository's path, not this machine's
