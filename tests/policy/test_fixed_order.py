"""The same bits on every CPU: the fixed-order kernels (rabbit_policy.runtime.fixed_order),
and whole walks of the three packaged controllers under other OpenBLAS kernels and NumPy
SIMD targets, compared bit for bit in one run."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rabbit_policy.runtime import fixed_order

ROOT = Path(__file__).resolve().parents[2]


# ------------------------------------------------------------------ the kernels
@pytest.mark.unit
def test_exp_and_tanh_are_within_a_few_ulp_of_libm():
    xs = np.concatenate([np.linspace(-40.0, 40.0, 20001), [0.0, -0.0, 1e-300, -1e-300, 700.0, -740.0]])
    for x in xs:
        e, t = fixed_order.exp(x), fixed_order.tanh(x)
        assert e == pytest.approx(math.exp(x), rel=4e-16, abs=0.0)
        assert abs(t - math.tanh(x)) <= 4e-16
    assert fixed_order.exp(710.0) == math.inf and fixed_order.exp(-746.0) == 0.0
    assert math.isnan(fixed_order.exp(math.nan)) and math.isnan(fixed_order.tanh(math.nan))
    assert fixed_order.tanh(math.inf) == 1.0 and fixed_order.tanh(-math.inf) == -1.0


@pytest.mark.unit
def test_products_add_their_terms_in_index_order():
    """matvec and vecmat equal a plain Python loop that adds the same terms one after another
    (a BLAS would add them in its own order: these values make the order visible)."""
    rng = np.random.default_rng(5)
    w = rng.normal(size=(7, 9)) * 10.0 ** rng.integers(-8, 9, size=(7, 9))
    h, b = rng.normal(size=9), rng.normal(size=7)
    expected = []
    for i in range(7):
        s = b[i]
        for j in range(9):
            s = s + w[i, j] * h[j]
        expected.append(s)
    assert fixed_order.matvec(w, h, b).tolist() == expected
    v = rng.normal(size=7)
    columns = []
    for j in range(9):
        s = 0.0
        for i in range(7):
            s = s + v[i] * w[i, j]
        columns.append(s)
    assert fixed_order.vecmat(v, w).tolist() == columns


# ------------------------------------------------------------------ whole walks
WALKS = """
import hashlib, json
import numpy as np
from rabbit_msgs_py.pushes import Push
from rabbit_policy.experiment.loop import walk
from rabbit_policy.spec.provenance import machine_record
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.spec.make import make_policy

demo = Scenario(schedule=((0.0, 0.8), (6.0, 1.4), (13.0, 0.9), (18.0, 1.2)), pushes=(Push(20.0, -60.0, 0.1),))
large_backward = Scenario.constant(1.0, pushes=tuple(Push(t, -150.0, 0.1) for t in (2.0, 4.0, 6.0)))
out = {"machine": machine_record()}
for name in ("classic", "recovery", "learned"):
    for label, scenario, duration in (("demo", demo, 26.0), ("large_backward", large_backward, 10.0)):
        r = walk(make_policy(name), scenario, duration, record_state=True)
        digest = hashlib.sha256()
        for a in (r.qpos, r.qvel, r.times, r.hip_x):
            digest.update(np.ascontiguousarray(a).tobytes())
        for d in r.decisions:
            digest.update(repr(d).encode())
        out[name + "/" + label] = [digest.hexdigest(), r.fell, r.stalled, r.steps]
print(json.dumps(out))
"""


def _walk(env: dict[str, str]) -> dict:
    done = subprocess.run([sys.executable, "-c", WALKS], capture_output=True, text=True, timeout=300, cwd=ROOT,
                          env={**os.environ, **env})
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout)


def _dispatched() -> list[str]:
    """NumPy's SIMD dispatch targets this CPU runs (NumPy 2.4: X86_V3, X86_V4, AVX512_ICL and, on
    Sapphire Rapids and later, AVX512_SPR)."""
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    return [name for name in __cpu_dispatch__ if __cpu_features__.get(name)]


def _avx512() -> bool:
    try:
        return " avx512f" in Path("/proc/cpuinfo").read_text()
    except OSError:
        return False


@pytest.mark.slow
@pytest.mark.sim
def test_the_three_controllers_walk_the_same_bits_under_every_kernel_and_simd_target():
    """The demo scenario and large_backward, for classic, recovery and learned, under OpenBLAS's
    Haswell, SkylakeX (where the CPU has AVX-512) and Prescott kernels and with NumPy's AVX-512
    and AVX2 dispatch off (every target the CPU has: NumPy 2.4 names them X86_V4/AVX512_ICL/
    AVX512_SPR and X86_V3; before, the fixed names missed AVX512_SPR on a Xeon): every tick's
    state, every decision, bit for bit. Before the fixed-order forward pass, learned fell in
    large_backward under SkylakeX and walked under the others."""
    kernels = ["Haswell", "Prescott"] + (["SkylakeX"] if _avx512() else [])
    settings = [{"OPENBLAS_CORETYPE": k} for k in kernels]
    dispatched = _dispatched()  # every target this CPU has, so the names fit an AMD EPYC and a Sapphire Rapids alike
    wide = [name for name in dispatched if name == "X86_V4" or name.startswith("AVX512")]
    settings += [{"NPY_DISABLE_CPU_FEATURES": ",".join(wide)} if wide else {},
                 {"NPY_DISABLE_CPU_FEATURES": ",".join(dispatched), "OPENBLAS_CORETYPE": "Prescott"}]
    runs = [(env, _walk(env)) for env in settings]
    machines = [run.pop("machine") for _env, run in runs]
    assert len({m["openblas_kernel"] for m in machines[:len(kernels)]}) == len(kernels), machines  # each its own
    assert machines[-1]["numpy_simd"] == [] and "X86_V4" not in machines[-2]["numpy_simd"], machines
    first_env, first = runs[0]
    assert len(first) == 6
    for env, run in runs[1:]:
        assert run == first, (env, first_env)


FMA_CHECK = """
from rabbit_policy.runtime import fixed_order
fixed_order.warm()
for kernel in (fixed_order.mlp, fixed_order.vecmat, fixed_order.matvec, fixed_order.exp, fixed_order.tanh):
    for signature in kernel.signatures:
        code = kernel.inspect_asm(signature).lower()
        assert "vmulsd" in code or "mulsd" in code or "vmulpd" in code, kernel  # real code, not a cached stub
        assert not any(op in code for op in ("vfmadd", "vfmsub", "vfnmadd", "vfnmsub")), kernel
"""


@pytest.mark.slow
@pytest.mark.unit
def test_the_compiled_kernels_use_no_fused_multiply_add(tmp_path):
    """An FMA rounds once where a multiply then an add round twice: a CPU with FMA would give
    other bits than one without. numba compiles without fast-math; the machine code (compiled
    afresh, into an empty cache: numba does not show cached code) shows it."""
    done = subprocess.run([sys.executable, "-c", FMA_CHECK], capture_output=True, text=True, timeout=300, cwd=ROOT,
                          env={**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)})
    assert done.returncode == 0, done.stderr[-3000:]
