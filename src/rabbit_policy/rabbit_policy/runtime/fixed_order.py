"""Arithmetic that gives the same bits on every x86-64 CPU, compiled (numba): the network's
forward pass and the matrix-vector products on the way from a state to a gait or a training
update.

Why: NumPy's ``w @ h`` goes through OpenBLAS, whose kernel (and so the order of its sums) is
chosen by the CPU, and NumPy's float32 ``exp``/``tanh`` are SIMD-dispatched (AVX-512, AVX2, or
baseline code, each its own polynomial). Either moves a decision by an ulp, and a walk that
is on the edge of a fall goes the other way on another machine (docs/learning.md,
2026-11-29).

How: every product is summed in float64, one term after another in index order; the only
operations are IEEE-754 ``+ - * /`` (each correctly rounded, so the same on every CPU;
numba compiles without fast-math, so nothing is reassociated or fused into an FMA: a test
reads the machine code) and ``math.ldexp`` (exact). ``exp`` and ``tanh`` are written here
from those operations rather than taken from libm or NumPy, whose code differs between
machines. They are accurate to a few ulp of float64, far below float32's rounding, which is
the precision the networks are trained in (torch, :mod:`.network`)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_LN2_HI = 6.93147180369123816490e-01
"""ln 2's upper bits (32 of them, so ``k * _LN2_HI`` is exact for |k| < 2**20): Cody and Waite's split."""
_LN2_LO = 1.90821492927058770002e-10
"""ln 2 - _LN2_HI."""
_INV_LN2 = 1.44269504088896338700e+00
_EXP_TERMS = 14
"""Taylor terms of exp(r) for |r| <= ln 2 / 2: the 14th is below 1e-17 of the sum."""

SIGMOID, CLIP, TANH = 0, 1, 2
"""The output maps :func:`mlp` knows (:data:`.forward.OUTPUTS`, in that order)."""


@njit(cache=True, nogil=True)
def exp(x: float) -> float:
    """e**x (float64) from ``+ - * /`` and ldexp: x = k ln 2 + r with |r| <= ln 2 / 2, e**r
    by its Taylor series in Horner's order, scaled by 2**k. 0 below -745, inf above 709.8."""
    if x != x:
        return x
    if x > 709.78:
        return math.inf
    if x < -745.2:
        return 0.0
    k = math.floor(x * _INV_LN2 + 0.5)
    r = (x - k * _LN2_HI) - k * _LN2_LO
    p = 1.0
    for n in range(_EXP_TERMS, 0, -1):
        p = 1.0 + p * r / n
    return math.ldexp(p, int(k))


@njit(cache=True, nogil=True)
def tanh(x: float) -> float:
    """tanh(x) (float64) as 1 - 2 / (e**(2|x|) + 1) with x's sign: within 2e-16 of it."""
    if x != x:
        return x
    a = abs(x)
    if a > 20.0:  # tanh(20) rounds to 1 in float64
        t = 1.0
    else:
        t = 1.0 - 2.0 / (exp(2.0 * a) + 1.0)
    return -t if x < 0.0 else t


@njit(cache=True, nogil=True)
def matvec(w: np.ndarray, h: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``w @ h + b`` (float64): each row's terms added to its bias in index order."""
    rows, cols = w.shape
    out = np.empty(rows)
    for i in range(rows):
        s = float(b[i])
        for j in range(cols):
            s = s + float(w[i, j]) * float(h[j])
        out[i] = s
    return out


@njit(cache=True, nogil=True)
def vecmat(v: np.ndarray, m: np.ndarray) -> np.ndarray:
    """``v @ m`` (float64): each column's terms added in row order, from 0."""
    rows, cols = m.shape
    out = np.zeros(cols)
    for i in range(rows):
        vi = float(v[i])
        for j in range(cols):
            out[j] = out[j] + vi * float(m[i, j])
    return out


@njit(cache=True, nogil=True)
def mlp(x: np.ndarray, offset: np.ndarray, scale: np.ndarray, params: np.ndarray, shapes: np.ndarray,
        output: int) -> np.ndarray:
    """A tanh network's action in [-1, 1] (float64 arrays in and out): inputs ``(x - offset) /
    scale``, layers ``params`` (each layer's weights row by row, then its bias; ``shapes[i]`` =
    (outputs, inputs)), tanh between layers, the last layer mapped by ``output``:
    :data:`SIGMOID` 2 / (1 + e**-h) - 1, :data:`CLIP` h clipped, :data:`TANH` tanh(h)."""
    h = np.empty(x.shape[0])
    for i in range(x.shape[0]):
        h[i] = (float(x[i]) - float(offset[i])) / float(scale[i])
    at = 0
    layers = shapes.shape[0]
    for layer in range(layers):
        rows, cols = shapes[layer, 0], shapes[layer, 1]
        w = params[at:at + rows * cols].reshape((rows, cols))
        at += rows * cols
        h = matvec(w, h, params[at:at + rows])
        at += rows
        if layer < layers - 1:
            for i in range(rows):
                h[i] = tanh(h[i])
    for i in range(h.shape[0]):
        if output == SIGMOID:
            h[i] = 2.0 / (1.0 + exp(-h[i])) - 1.0
        elif output == CLIP:
            h[i] = min(max(h[i], -1.0), 1.0)
        else:
            h[i] = tanh(h[i])
    return h


def pack_layers(weights, biases) -> tuple[np.ndarray, np.ndarray]:
    """(params, shapes) for :func:`mlp`: each layer's weights row by row then its bias, as float64."""
    params = np.concatenate([np.concatenate([np.asarray(w, dtype=np.float64).ravel(),
                                             np.asarray(b, dtype=np.float64)]) for w, b in zip(weights, biases)])
    shapes = np.array([np.shape(w) for w in weights], dtype=np.int64)
    return params, shapes


def warm() -> None:
    """Load (or compile) the kernels now, not on a node's first decision."""
    params, shapes = pack_layers([np.ones((2, 1))], [np.zeros(2)])
    for output in (SIGMOID, CLIP, TANH):
        mlp(np.ones(1), np.zeros(1), np.ones(1), params, shapes, output)
    vecmat(np.ones(2), np.ones((2, 2)))
