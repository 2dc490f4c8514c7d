"""``exp``, ``sin``, ``cos`` and the logistic sigmoid in float64, from IEEE-754 basic
operations only, so that their bits do not depend on the CPU.

numpy's ``np.tanh``/``np.exp`` run on kernels chosen by the CPU at import (numpy's dispatch:
AVX2/FMA or AVX-512 loops, or the C library), and glibc's ``sin``/``cos``/``exp`` choose
FMA or non-FMA code by the CPU too; measured here, each gives other last bits with those
features disabled. Algorithm 1's fitness is chaotic in those bits (a bang-bang policy's
crash step flips on a rounding), so the simulator and the Actor's greedy forward pass use
these functions instead: every operation below is ``+``, ``-``, ``*``, ``/``, ``rint``,
``ldexp``, a comparison or a selection, each correctly rounded by IEEE 754 and evaluated
one ufunc call at a time (numpy never fuses two calls into an FMA), so a result is the same
on every IEEE-754 machine, whatever the batch, the position of a row or numpy's dispatch.

Accuracy is that of fdlibm's kernels (about 1 ulp); what matters here is that the value is
defined, not that it is correctly rounded.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["cos", "exp", "sigmoid", "sin", "sin_cos"]

# exp: x = k ln2 + r, |r| <= ln2 / 2; ln2 split so that k * LN2_HI is exact for |k| < 2^11.
LN2_HI = 6.93147180369123816490e-01
LN2_LO = 1.90821492927058770002e-10
INV_LN2 = 1.44269504088896338700e00
EXP_LIMIT = 708.0  # beyond, the result is clamped: exp(+-708) is finite in float64
# Taylor coefficients 1/k! for k = 2..13 (ascending): on |r| <= 0.347 the tail is
# below 1e-17 relative.
EXP_COEFFS = tuple(1.0 / math.factorial(k) for k in range(2, 14))

# sin/cos: x = n pi/2 + r, |r| <= pi/4; pi/2 split into three 33-bit parts and a tail
# (Cody-Waite with fdlibm's values), so n * part is exact for |n| < 2^20.
TWO_OVER_PI = 6.36619772367581382433e-01
PIO2_1 = 1.57079632673412561417e00
PIO2_2 = 6.07710050630396597660e-11
PIO2_3 = 2.02226624871116645580e-21
PIO2_3T = 8.47842766036889956997e-32
SIN_LIMIT = 1.0e5  # Cody-Waite reduction is exact enough far beyond the angles used here
# fdlibm __kernel_sin / __kernel_cos coefficients.
S = (
    -1.66666666666666324348e-01,
    8.33333333332248946124e-03,
    -1.98412698298579493134e-04,
    2.75573137070700676789e-06,
    -2.50507602534068634195e-08,
    1.58969099521155010221e-10,
)
C = (
    4.16666666666666019037e-02,
    -1.38888888888741095749e-03,
    2.48015872894767294178e-05,
    -2.75573143513906633035e-07,
    2.08757232129817482790e-09,
    -1.13596475577881948265e-11,
)


def _horner(z: np.ndarray, coeffs: tuple[float, ...]) -> np.ndarray:
    """``coeffs[0] + z (coeffs[1] + z (...))``, one multiply and one add at a time."""
    acc = np.full_like(z, coeffs[-1])
    for c in coeffs[-2::-1]:
        acc = acc * z
        acc = acc + c
    return acc


def exp(x: np.ndarray) -> np.ndarray:
    """``e**x`` in float64 (inputs clamped to [-708, 708]; NaN stays NaN)."""
    x = np.clip(np.asarray(x, dtype=np.float64), -EXP_LIMIT, EXP_LIMIT)
    k = np.rint(x * INV_LN2)
    r = (x - k * LN2_HI) - k * LN2_LO
    # 1 + r + r^2 (1/2! + r (1/3! + ...)): the polynomial from 1/13! down to 1/2!
    p = _horner(r, EXP_COEFFS)
    p = p * (r * r)
    p = p + r
    p = p + 1.0
    return np.ldexp(p, np.nan_to_num(k).astype(np.int64))


def _kernel_sin(r: np.ndarray) -> np.ndarray:
    z = r * r
    poly = _horner(z, S)
    return r + (r * z) * poly


def _kernel_cos(r: np.ndarray) -> np.ndarray:
    z = r * r
    poly = _horner(z, C)
    return (1.0 - 0.5 * z) + (z * z) * poly


def sin_cos(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(sin x, cos x)`` in float64 for ``|x| <= 1e5`` (one shared range reduction)."""
    x = np.asarray(x, dtype=np.float64)
    if np.any(np.abs(x) > SIN_LIMIT):
        raise ValueError(f"sin/cos arguments must lie within +-{SIN_LIMIT:g}")
    n = np.rint(x * TWO_OVER_PI)
    r = (((x - n * PIO2_1) - n * PIO2_2) - n * PIO2_3) - n * PIO2_3T
    s, c = _kernel_sin(r), _kernel_cos(r)
    quadrant = np.nan_to_num(n).astype(np.int64) & 3
    sin = np.where(quadrant == 0, s, np.where(quadrant == 1, c, np.where(quadrant == 2, -s, -c)))
    cos = np.where(quadrant == 0, c, np.where(quadrant == 1, -s, np.where(quadrant == 2, -c, s)))
    return sin, cos


def sin(x: np.ndarray) -> np.ndarray:
    """``sin x`` in float64 for ``|x| <= 1e5``."""
    return sin_cos(x)[0]


def cos(x: np.ndarray) -> np.ndarray:
    """``cos x`` in float64 for ``|x| <= 1e5``."""
    return sin_cos(x)[1]


def sigmoid(z: np.ndarray) -> np.ndarray:
    """The logistic function ``1 / (1 + e**-z)`` in float64 (overflow-free: ``exp`` clamps)."""
    denominator = exp(-np.asarray(z, dtype=np.float64))
    denominator = denominator + 1.0
    return 1.0 / denominator
