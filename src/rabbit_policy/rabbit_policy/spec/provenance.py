"""What a run ran on: the code's commit and the machine's numerics (CPU, the SIMD NumPy
dispatches to, OpenBLAS's kernel, and the versions of NumPy, MuJoCo and numba), recorded
beside every result so a number can be traced to the code and the arithmetic that made it.
The decision path computes in a fixed order (:mod:`rabbit_policy.runtime.fixed_order`), so
the machine should not move a result; the record is there to show it."""

from __future__ import annotations

import ctypes
import hashlib
import platform
import subprocess
import sys
from pathlib import Path

import mujoco
import numba
import numpy as np

_OPENBLAS_CORENAME = ("scipy_openblas_get_corename64_", "scipy_openblas_get_corename", "openblas_get_corename64_",
                      "openblas_get_corename")


def code_commit(root: Path | None = None) -> str:
    """The git commit of the code here ("unknown" outside a checkout), "+dirty" if changed."""
    root = root or Path(__file__).resolve().parents[3]
    try:
        sha = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True,
                             timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=root,
                               capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return (sha + ("+dirty" if dirty else "")) if sha else "unknown"


class DirtyTree(RuntimeError):
    """What ships is written from a checkout with changes no commit holds."""


def shipping_provenance(allow_dirty: bool, root: Path | None = None) -> dict:
    """The provenance of something that ships (a spec, a card): :func:`provenance`, refused
    with :class:`DirtyTree` when the checkout has uncommitted changes unless ``allow_dirty``,
    then recorded with ``dirty_diff_sha256`` (the SHA-256 of ``git diff HEAD``)."""
    record = provenance(root)
    if not record["code_commit"].endswith("+dirty"):
        return record
    if not allow_dirty:
        raise DirtyTree("the checkout has uncommitted changes, so no commit says what made this: commit them, or "
                        "pass --allow-dirty (the diff's hash is then recorded)")
    root = root or Path(__file__).resolve().parents[3]
    diff = subprocess.run(["git", "diff", "HEAD"], cwd=root, capture_output=True, timeout=30).stdout
    return {**record, "dirty_diff_sha256": hashlib.sha256(diff).hexdigest()}


def cpu_model() -> str:
    """The CPU's model name (Linux: /proc/cpuinfo; elsewhere what Python's platform says)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def numpy_simd() -> list[str]:
    """The SIMD targets NumPy dispatches to on this CPU (after ``NPY_DISABLE_CPU_FEATURES``)."""
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    return [name for name in __cpu_dispatch__ if __cpu_features__.get(name)]


def openblas_kernel() -> str:
    """The kernel OpenBLAS chose for this CPU (``OPENBLAS_CORETYPE`` forces one), or "unknown"."""
    try:
        maps = Path("/proc/self/maps").read_text().splitlines()
    except OSError:
        return "unknown"
    libraries = sorted({line.split()[-1] for line in maps if "openblas" in line.rsplit("/", 1)[-1].lower()})
    for path in libraries:
        library = ctypes.CDLL(path)
        for symbol in _OPENBLAS_CORENAME:
            function = getattr(library, symbol, None)
            if function is not None:
                function.restype = ctypes.c_char_p
                return function().decode()
    return "unknown"


def machine_record() -> dict:
    """The machine's numerics: CPU, NumPy's SIMD targets, OpenBLAS's kernel and version,
    and the versions of Python, NumPy, MuJoCo and numba."""
    blas = np.__config__.CONFIG.get("Build Dependencies", {}).get("blas", {})
    return {"cpu": cpu_model(), "numpy_simd": numpy_simd(), "openblas_kernel": openblas_kernel(),
            "openblas": str(blas.get("version", "unknown")), "python": platform.python_version(),
            "numpy": np.__version__, "mujoco": mujoco.__version__, "numba": numba.__version__,
            "platform": f"{sys.platform}-{platform.machine()}"}


def provenance(root: Path | None = None) -> dict:
    """The code's commit (:func:`code_commit`) and the machine (:func:`machine_record`)."""
    return {"code_commit": code_commit(root), "machine": machine_record()}
