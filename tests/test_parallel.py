"""The execution backends (rabbit_policy.parallel): the local process pool gives the same
ES answer for any number of workers; the Ray backend is not tested here yet (it is not
delivered: see docs/learning.md)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from rabbit_policy.learning.env import RabbitHZDEnv
from rabbit_policy.learning.es import ESConfig, EvolutionStrategy
from rabbit_policy.parallel import BackendConfig, LocalBackend, make_backend
from rabbit_policy.runtime.network import HZDPolicyNet

ROOT = Path(__file__).resolve().parents[1]


def test_backend_config_rejects_bad_input():
    for kwargs in ({"kind": "spark"}, {"workers": 0}, {"workers": 1.5}, {"kind": "local", "address": "auto"}):
        with pytest.raises(ValueError):
            BackendConfig(**kwargs)
    backend = make_backend(BackendConfig("local", 1))
    assert backend.map(abs, [-1, 2, -3]) == [1, 2, 3]  # one worker: in this process, in order
    backend.close()


def _es_run(backend) -> tuple[np.ndarray, list[dict]]:
    env = RabbitHZDEnv()
    torch.manual_seed(0)
    net = HZDPolicyNet(env.bounds.low, env.bounds.high)
    es = EvolutionStrategy(net, ESConfig(pairs=2, episodes=2, max_steps=4, workers=2, seed=3), backend)
    stats = [es.step() for _ in range(2)]
    return es.theta.copy(), stats


def test_es_on_the_local_backend_is_the_same_for_one_or_two_workers():
    one, two = LocalBackend(1), LocalBackend(2)
    try:
        theta_one, stats_one = _es_run(one)
        theta_two, stats_two = _es_run(two)
    finally:
        one.close()
        two.close()
    assert np.array_equal(theta_one, theta_two) and stats_one == stats_two


def test_without_ray_installed_the_ray_backend_is_one_line():
    import importlib.util

    if importlib.util.find_spec("ray") is not None:
        pytest.skip("ray is installed here")
    result = subprocess.run([sys.executable, "scripts/train.py", "--algo", "es", "--out", "/tmp/never",
                             "--backend", "ray"], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert result.returncode == 2 and result.stderr.strip() == \
        "error: --backend ray needs the ray package (pip install ray==2.60.0)"
