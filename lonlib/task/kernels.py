"""The one rollout compiled with numba: the same arithmetic as the numpy definition, row by row.

This module is the numba half of :mod:`lonlib.task.compiled`, which imports it lazily (never
at ``import lonlib``), after setting numba's cache folder and switching Intel SVML off. Each
function below mirrors, operation for operation, its numpy definition, which stays the test
oracle:

* :func:`exp`, :func:`sin_cos`, :func:`sigmoid`: :mod:`lonlib.util.portable_math`;
* :func:`sensors_row`, :func:`step_row`: :meth:`lonlib.task.pendulum.CoupledPendulums.observe`
  and ``step`` (via ``_accelerations`` and ``_termination_reason``);
* :func:`actor_row`: :func:`lonlib.task.policy.forward_numpy`;
* :func:`rollout`: :func:`lonlib.task.rollout.run_policy` for flat Actors.

What keeps the bits those of numpy (docs/rollout.md): no ``fastmath`` (LLVM then never fuses a
multiply and an add into an FMA, nor reorders a sum; a test reads the assembly);
``error_model="numpy"`` (a division by zero gives inf/NaN as in numpy instead of raising);
only ``+ - * /``, comparisons, ``rint``, ``ldexp`` and ``fmod``, each exactly defined by IEEE
754 and C99; numpy's own ``clip``, ``maximum``, ``minimum``, ``sign`` and ``mod`` semantics
for signed zeros and NaN, written out; every sum seeded with its first term, never with 0.0
(``0.0 + -0.0`` is ``+0.0``), summed from index 0 upwards.

The configuration reaches the kernels as runtime arrays (:func:`lonlib.task.compiled.pack`),
so one compilation serves every configuration and batch.
"""

from __future__ import annotations

import math

import numpy as np
from numba import config as numba_config
from numba import njit, prange

from lonlib.task.kernel_config import (
    F_ANGULAR_VELOCITY_RANGE,
    F_CART_FRICTION,
    F_CART_MASS,
    F_CART_WIDTH,
    F_COS_UPRIGHT,
    F_DT,
    F_GRAVITY,
    F_HINGE_FRICTION,
    F_MOTOR_GAIN,
    F_MOTOR_TAU,
    F_PENALTY,
    F_POLE_HALF_LENGTH,
    F_POLE_MASS,
    F_TETHER,
    F_TRACK_HALF,
    F_VELOCITY_RANGE,
    I_FITNESS_MEAN,
    I_INTEGRATOR_EULER,
    I_MOTOR,
    I_N_CARTS,
    I_REWARD,
    I_STEPS,
    I_SUBSTEPS,
    MOTOR_ACCELERATION,
    MOTOR_FORCE,
    REWARD_HEIGHT_PRODUCT,
    REWARD_SLOW_HEIGHT,
    REWARD_UPRIGHT,
)
from lonlib.util.portable_math import (
    EXP_COEFFS,
    EXP_LIMIT,
    INV_LN2,
    LN2_HI,
    LN2_LO,
    PIO2_1,
    PIO2_2,
    PIO2_3,
    PIO2_3T,
    SIN_LIMIT,
    TWO_OVER_PI,
    C,
    S,
)

# Cache only where lonlib.task.compiled found a writable, version-keyed folder.
CACHE = bool(numba_config.CACHE_DIR)
_EXP_C = np.array(EXP_COEFFS)
_SIN_C = np.array(S)
_COS_C = np.array(C)
_TWO_PI = 2 * np.pi
_HALF_PI = 0.5 * np.pi
# EndReason values (lonlib.task.pendulum.EndReason)
RUNNING, STEP_LIMIT, COLLISION, TETHER, BOUNDARY = 0, 1, 2, 3, 4


# --------------------------------------------------------------------- portable math
def _horner(z: float, coeffs: np.ndarray) -> float:
    acc = coeffs[coeffs.shape[0] - 1]
    for j in range(coeffs.shape[0] - 2, -1, -1):
        acc = acc * z
        acc = acc + coeffs[j]
    return acc


def _clip(x: float, low: float, high: float) -> float:
    """numpy's ``clip``: ``x < low`` then ``x > high`` (NaN and -0.0 kept as they are)."""
    if x < low:
        x = low
    if x > high:
        x = high
    return x


def _maximum(a: float, b: float) -> float:
    """numpy's ``maximum``: NaN wins; of two equal values (``-0.0, 0.0``) the second."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a > b else b


def _minimum(a: float, b: float) -> float:
    """numpy's ``minimum``: NaN wins; of two equal values the second."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a < b else b


def _sign(x: float) -> float:
    """numpy's ``sign``: 1, -1, 0.0 for either zero, NaN for NaN."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    if x == 0.0:
        return 0.0
    return x


def _mod(a: float, b: float) -> float:
    """numpy's (and Python's) float ``mod``: ``fmod``, moved into ``b``'s sign, +0.0 for 0."""
    m = np.fmod(a, b)
    if m != 0.0:
        if (b < 0.0) != (m < 0.0):
            m = m + b
    else:
        m = math.copysign(0.0, b)
    return m


def _to_int(k: float) -> int:
    """``np.nan_to_num(k).astype(np.int64)`` for the small integral ``k`` used here."""
    if k != k:
        return 0
    return int(k)


def exp(x: float) -> float:
    """:func:`lonlib.util.portable_math.exp` for one float."""
    x = _clip(x, -EXP_LIMIT, EXP_LIMIT)
    k = np.rint(x * INV_LN2)
    r = (x - k * LN2_HI) - k * LN2_LO
    p = _horner(r, _EXP_C)
    p = p * (r * r)
    p = p + r
    p = p + 1.0
    return math.ldexp(p, _to_int(k))


def sin_cos(x: float) -> tuple[float, float]:
    """:func:`lonlib.util.portable_math.sin_cos` for one float."""
    if abs(x) > SIN_LIMIT:
        raise ValueError("sin/cos arguments must lie within +-1e+05")
    n = np.rint(x * TWO_OVER_PI)
    r = (((x - n * PIO2_1) - n * PIO2_2) - n * PIO2_3) - n * PIO2_3T
    z = r * r
    s = r + (r * z) * _horner(z, _SIN_C)
    c = (1.0 - 0.5 * z) + (z * z) * _horner(z, _COS_C)
    quadrant = _to_int(n) & 3
    if quadrant == 0:
        return s, c
    if quadrant == 1:
        return c, -s
    if quadrant == 2:
        return -s, -c
    return -c, s


def sigmoid(z: float) -> float:
    """:func:`lonlib.util.portable_math.sigmoid` for one float."""
    denominator = exp(-z)
    denominator = denominator + 1.0
    return 1.0 / denominator


# --------------------------------------------------------------------- the Actor
def actor_row(
    theta: np.ndarray, sizes: np.ndarray, inputs: np.ndarray, out: np.ndarray, work: np.ndarray
) -> None:
    """:func:`lonlib.task.policy.forward_numpy` of one flat Actor ``theta`` (float64) on one
    input row, into ``out``; ``work [2, max width]`` is scratch. Every layer ends in the
    sigmoid (the Actor's spec)."""
    n_layers = sizes.shape[0] - 1
    for i in range(sizes[0]):
        work[0, i] = inputs[i]
    start = 0
    src = 0
    for layer in range(n_layers):
        fan_in = sizes[layer]
        fan_out = sizes[layer + 1]
        bias = start + fan_in * fan_out
        dst = 1 - src
        for o in range(fan_out):
            row = start + o * fan_in
            acc = theta[row] * work[src, 0]
            for i in range(1, fan_in):
                acc = acc + theta[row + i] * work[src, i]
            work[dst, o] = sigmoid(acc + theta[bias + o])
        start = bias + fan_out
        src = dst
    for o in range(sizes[n_layers]):
        out[o] = work[src, o]


# --------------------------------------------------------------------- the simulator
def sensors_row(
    fc: np.ndarray,
    ic: np.ndarray,
    x: np.ndarray,
    x_dot: np.ndarray,
    phi: np.ndarray,
    phi_dot: np.ndarray,
    out: np.ndarray,
) -> None:
    """:func:`lonlib.task.pendulum.sensors` of one environment (``[n]`` state) into
    ``out [10 n]``."""
    n = ic[I_N_CARTS]
    width = fc[F_CART_WIDTH]
    tether = fc[F_TETHER]
    wall = fc[F_TRACK_HALF] + 0.5 * width
    span = tether - width
    for c in range(n):
        q = phi[c] / _HALF_PI
        o = 10 * c
        out[o] = 1.0 - q if q < 1.0 else 0.0
        out[o + 1] = q - 3.0 if q >= 3.0 else 0.0
        out[o + 2] = 2.0 - q if (q >= 1.0) and (q < 2.0) else 0.0
        out[o + 3] = q - 2.0 if (q >= 2.0) and (q < 3.0) else 0.0
        left = x[c] - -wall if c == 0 else x[c] - x[c - 1]
        right = wall - x[c] if c == n - 1 else x[c + 1] - x[c]
        out[o + 4] = _clip((tether - left) / span, 0.0, 1.0)
        out[o + 5] = _clip((tether - right) / span, 0.0, 1.0)
        v = _clip(x_dot[c] / fc[F_VELOCITY_RANGE], -1.0, 1.0)
        w = _clip(phi_dot[c] / fc[F_ANGULAR_VELOCITY_RANGE], -1.0, 1.0)
        out[o + 6] = _maximum(-v, 0.0)
        out[o + 7] = _maximum(v, 0.0)
        out[o + 8] = _maximum(-w, 0.0)
        out[o + 9] = _maximum(w, 0.0)


def _accelerations(
    fc: np.ndarray, motor: int, x_dot: float, phi: float, phi_dot: float, drive: float
) -> tuple[float, float]:
    """``CoupledPendulums._accelerations`` of one cart."""
    m = fc[F_POLE_MASS]
    l = fc[F_POLE_HALF_LENGTH]
    g = fc[F_GRAVITY]
    sin, cos = sin_cos(phi)
    if motor == MOTOR_FORCE:
        total = fc[F_CART_MASS] + m
        friction = fc[F_CART_FRICTION] * _sign(x_dot)
        temp = (-drive - m * l * (phi_dot * phi_dot) * sin + friction) / total
        phi_ddot = (g * sin + cos * temp - fc[F_HINGE_FRICTION] * phi_dot / (m * l)) / (
            l * (4.0 / 3.0 - m * (cos * cos) / total)
        )
        x_ddot = (drive + m * l * ((phi_dot * phi_dot) * sin - phi_ddot * cos) - friction) / total
    else:
        if motor == MOTOR_ACCELERATION:
            x_ddot = drive
        else:
            x_ddot = (drive - x_dot) / fc[F_MOTOR_TAU]
        phi_ddot = 0.75 / l * (g * sin - x_ddot * cos) - 0.75 * fc[F_HINGE_FRICTION] * (
            phi_dot / (m * l * l)
        )
    return x_ddot, phi_ddot


def _advance(
    fc: np.ndarray,
    ic: np.ndarray,
    x: np.ndarray,
    x_dot: np.ndarray,
    phi: np.ndarray,
    phi_dot: np.ndarray,
    actions: np.ndarray,
) -> None:
    """The physics of one control step of one environment, in place (angles wrapped)."""
    substeps = ic[I_SUBSTEPS]
    motor = ic[I_MOTOR]
    euler = ic[I_INTEGRATOR_EULER] == 1
    h = fc[F_DT] / substeps
    gain = -fc[F_MOTOR_GAIN]
    for c in range(ic[I_N_CARTS]):
        drive = gain * (2.0 - 4.0 * _clip(actions[c], 0.0, 1.0))
        xc, vc, pc, wc = x[c], x_dot[c], phi[c], phi_dot[c]
        for _ in range(substeps):
            x_ddot, phi_ddot = _accelerations(fc, motor, vc, pc, wc, drive)
            if euler:
                xc, pc = xc + h * vc, pc + h * wc
                vc, wc = vc + h * x_ddot, wc + h * phi_ddot
            else:
                vc, wc = vc + h * x_ddot, wc + h * phi_ddot
                xc, pc = xc + h * vc, pc + h * wc
        x[c], x_dot[c], phi[c], phi_dot[c] = xc, vc, _mod(pc, _TWO_PI), wc


def _rods(
    fc: np.ndarray, ic: np.ndarray, phi: np.ndarray, phi_dot: np.ndarray, upright_each: np.ndarray
) -> tuple[int, float]:
    """Each rod's upright flag (into ``upright_each``), their count and the shaped reward
    (before the termination penalty) of the state."""
    n = ic[I_N_CARTS]
    reward_kind = ic[I_REWARD]
    count = 0
    shaped = 0.0
    for c in range(n):
        cos = sin_cos(phi[c])[1]
        upright_each[c] = cos > fc[F_COS_UPRIGHT]
        count += upright_each[c]
        height = 0.5 * (1.0 + cos)
        if reward_kind == REWARD_SLOW_HEIGHT:
            speed = abs(phi_dot[c]) / fc[F_ANGULAR_VELOCITY_RANGE]
            height = height * (1.0 - _minimum(speed, 1.0))
        if c == 0:
            shaped = height
        elif reward_kind == REWARD_HEIGHT_PRODUCT:
            shaped = shaped * height
        else:
            shaped = shaped + height
    if reward_kind != REWARD_HEIGHT_PRODUCT:
        shaped = shaped / n
    return count, shaped


def _end_reason(fc: np.ndarray, ic: np.ndarray, x: np.ndarray) -> int:
    """``CoupledPendulums._termination_reason`` of one environment."""
    width = fc[F_CART_WIDTH]
    reason = RUNNING
    for c in range(ic[I_N_CARTS]):
        if abs(x[c]) + 0.5 * width > fc[F_TRACK_HALF]:
            reason = BOUNDARY
    tether = False
    collision = False
    for c in range(ic[I_N_CARTS] - 1):
        gap = x[c + 1] - x[c]
        tether = tether or gap > fc[F_TETHER]
        collision = collision or gap < width
    if tether:
        reason = TETHER
    if collision:
        reason = COLLISION
    return reason


def step_row(
    fc: np.ndarray,
    ic: np.ndarray,
    x: np.ndarray,
    x_dot: np.ndarray,
    phi: np.ndarray,
    phi_dot: np.ndarray,
    sums: np.ndarray,
    steps_done: int,
    actions: np.ndarray,
    upright_each: np.ndarray,
) -> tuple[float, float, int, bool, bool]:
    """``CoupledPendulums.step`` of one **running** environment, in place.

    ``sums [3]`` are the upright sums (by the fitness mode, every rod, the mean);
    ``steps_done`` counts this step. Returns ``(reward, upright, end reason, terminated,
    truncated)``.
    """
    _advance(fc, ic, x, x_dot, phi, phi_dot, actions)
    n = ic[I_N_CARTS]
    count, shaped = _rods(fc, ic, phi, phi_dot, upright_each)
    upright_all = 1.0 if count == n else 0.0
    upright_mean = count / n
    sums[1] = sums[1] + upright_all
    sums[2] = sums[2] + upright_mean
    upright = upright_mean if ic[I_FITNESS_MEAN] == 1 else upright_all
    sums[0] = sums[0] + upright
    reason = _end_reason(fc, ic, x)
    terminated = reason != RUNNING
    truncated = (not terminated) and steps_done >= ic[I_STEPS]
    if truncated:
        reason = STEP_LIMIT
    if ic[I_REWARD] == REWARD_UPRIGHT:
        reward = upright / ic[I_STEPS]
    else:
        reward = shaped + fc[F_PENALTY] * (1.0 if terminated else 0.0)
    return reward, upright, reason, terminated, truncated


# --------------------------------------------------------------------- batched entry points
def observe_batch(
    fc: np.ndarray,
    ic: np.ndarray,
    x: np.ndarray,
    x_dot: np.ndarray,
    phi: np.ndarray,
    phi_dot: np.ndarray,
    out: np.ndarray,
) -> None:
    """``CoupledPendulums.observe`` of ``B`` environments into ``out [B, 10 n]``."""
    for b in range(x.shape[0]):
        sensors_row(fc, ic, x[b], x_dot[b], phi[b], phi_dot[b], out[b])


def step_batch(
    fc: np.ndarray,
    ic: np.ndarray,
    x: np.ndarray,
    x_dot: np.ndarray,
    phi: np.ndarray,
    phi_dot: np.ndarray,
    step_count: np.ndarray,
    sums: np.ndarray,
    end_reason: np.ndarray,
    actions: np.ndarray,
    reward: np.ndarray,
    upright: np.ndarray,
    upright_each: np.ndarray,
    terminated: np.ndarray,
    truncated: np.ndarray,
    reported: np.ndarray,
) -> None:
    """``CoupledPendulums.step`` of ``B`` environments in place (``sums [B, 3]``), its
    :class:`~lonlib.task.pendulum.StepResult` arrays written into the last six. Ended
    environments do not move: their reward is the frozen state's shaped reward times 0.0
    and their upright values 0, as in numpy's masked step."""
    for b in range(x.shape[0]):
        if end_reason[b] != RUNNING:
            _, shaped = _rods(fc, ic, phi[b], phi_dot[b], upright_each[b])
            for c in range(upright_each.shape[1]):
                upright_each[b, c] = False
            if ic[I_REWARD] == REWARD_UPRIGHT:
                shaped = 0.0 / ic[I_STEPS]
            reward[b] = (shaped + fc[F_PENALTY] * 0.0) * 0.0
            upright[b] = 0.0
            terminated[b] = False
            truncated[b] = False
            reported[b] = RUNNING
            continue
        step_count[b] += 1
        r, u, reason, term, trunc = step_row(
            fc,
            ic,
            x[b],
            x_dot[b],
            phi[b],
            phi_dot[b],
            sums[b],
            step_count[b],
            actions[b],
            upright_each[b],
        )
        reward[b] = r
        upright[b] = u
        terminated[b] = term
        truncated[b] = trunc
        end_reason[b] = reason
        reported[b] = reason


def rollout(
    fc: np.ndarray,
    ic: np.ndarray,
    sizes: np.ndarray,
    thetas: np.ndarray,
    which: np.ndarray,
    x0: np.ndarray,
    x_dot0: np.ndarray,
    phi0: np.ndarray,
    phi_dot0: np.ndarray,
    sums: np.ndarray,
    end_reason: np.ndarray,
    end_step: np.ndarray,
    episode_return: np.ndarray,
    trace_state: np.ndarray,
    trace_sensors: np.ndarray,
    trace_actions: np.ndarray,
    trace_upright: np.ndarray,
    trace_fitness: np.ndarray,
) -> None:
    """Greedy episodes of flat Actors, one row per environment, rows in parallel.

    Row ``b`` starts from ``x0[b]`` ... (the reset state) and acts with ``thetas[which[b]]``
    until it ends. Its upright sums go to ``sums [B, 3]``, its end to ``end_reason`` and
    ``end_step``, its reward sum to ``episode_return``. The first ``k`` rows
    (``trace_fitness [S, k]``, ``S`` = the episode length) keep every step: ``trace_state
    [S, 4, k, n]`` after the step, the sensors before it, the actions, the upright flags and
    the running fitness; a row's steps after its end repeat its final state, as the numpy
    loop (which goes on until every row has ended) stores them.
    """
    n = ic[I_N_CARTS]
    steps = ic[I_STEPS]
    kept = trace_fitness.shape[1]
    width = max(sizes.max(), 10 * n)
    for b in prange(x0.shape[0]):
        theta = thetas[which[b]]
        x = x0[b].copy()
        x_dot = x_dot0[b].copy()
        phi = phi0[b].copy()
        phi_dot = phi_dot0[b].copy()
        observation = np.empty(10 * n)
        actions = np.empty(n)
        upright_each = np.zeros(n, dtype=np.bool_)
        work = np.empty((2, width))
        total = 0.0
        t = 0
        reason = RUNNING
        while reason == RUNNING:
            sensors_row(fc, ic, x, x_dot, phi, phi_dot, observation)
            actor_row(theta, sizes, observation, actions, work)
            t += 1
            r, _, reason, _, _ = step_row(
                fc, ic, x, x_dot, phi, phi_dot, sums[b], t, actions, upright_each
            )
            total = total + r
            if b < kept:
                _keep(trace_state, t - 1, b, x, x_dot, phi, phi_dot)
                trace_sensors[t - 1, b] = observation
                trace_actions[t - 1, b] = actions
                trace_upright[t - 1, b] = upright_each
                trace_fitness[t - 1, b] = sums[b, 0] / steps
        end_reason[b] = reason
        end_step[b] = t
        episode_return[b] = total
        if b < kept and t < steps:  # the frozen final state, as the numpy loop keeps it
            sensors_row(fc, ic, x, x_dot, phi, phi_dot, observation)
            actor_row(theta, sizes, observation, actions, work)
            for s in range(t, steps):
                _keep(trace_state, s, b, x, x_dot, phi, phi_dot)
                trace_sensors[s, b] = observation
                trace_actions[s, b] = actions
                trace_upright[s, b] = False
                trace_fitness[s, b] = sums[b, 0] / steps


def _keep(
    trace_state: np.ndarray,
    s: int,
    b: int,
    x: np.ndarray,
    x_dot: np.ndarray,
    phi: np.ndarray,
    phi_dot: np.ndarray,
) -> None:
    trace_state[s, 0, b] = x
    trace_state[s, 1, b] = x_dot
    trace_state[s, 2, b] = phi
    trace_state[s, 3, b] = phi_dot


# --------------------------------------------------------------------- compilation
def _compile() -> None:
    """Replace the functions above by their numba-compiled versions (once, at import)."""
    options = {"cache": CACHE, "error_model": "numpy", "fastmath": False, "nogil": True}
    names = [
        "_horner", "_clip", "_maximum", "_minimum", "_sign", "_mod", "_to_int", "exp",
        "sin_cos", "sigmoid", "actor_row", "sensors_row", "_accelerations", "_advance",
        "_rods", "_end_reason", "step_row", "observe_batch", "step_batch", "_keep",
    ]  # fmt: skip
    scope = globals()
    for name in names:
        scope[name] = njit(**options)(scope[name])
    scope["rollout"] = njit(parallel=True, **options)(scope["rollout"])


_compile()


# --------------------------------------------------------------------- calls from numpy
def rollout_actors(
    fc: np.ndarray,
    ic: np.ndarray,
    sizes: np.ndarray,
    thetas: np.ndarray,
    which: np.ndarray,
    start: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    kept: int,
) -> dict[str, np.ndarray]:
    """Run :func:`rollout` from the reset state ``start`` (x, x_dot, phi, phi_dot, each
    ``[B, n]``) and return its arrays: ``sums [B, 3]``, ``end_reason``, ``end_step``,
    ``episode_return`` and, for the first ``kept`` rows, the trace arrays cut to the longest
    episode (``x``, ``x_dot``, ``phi``, ``phi_dot``, ``sensors``, ``actions``, ``upright``,
    ``fitness``, each ``[T, kept, ...]``)."""
    batch, n = start[0].shape
    steps = int(ic[I_STEPS]) if kept else 0
    out = {
        "sums": np.zeros((batch, 3)),
        "end_reason": np.zeros(batch, dtype=np.int8),
        "end_step": np.zeros(batch, dtype=np.int64),
        "episode_return": np.zeros(batch),
    }
    state = np.zeros((steps, 4, kept, n))
    trace = {
        "sensors": np.zeros((steps, kept, 10 * n)),
        "actions": np.zeros((steps, kept, n)),
        "upright": np.zeros((steps, kept, n), dtype=np.bool_),
        "fitness": np.zeros((steps, kept)),
    }
    try:
        rollout(
            fc, ic, sizes, thetas, which, *(np.ascontiguousarray(s) for s in start),
            out["sums"], out["end_reason"], out["end_step"], out["episode_return"],
            state, trace["sensors"], trace["actions"], trace["upright"], trace["fitness"],
        )  # fmt: skip
    except SystemError as error:
        # numba's parallel loop reports what a row raised (a diverging episode's sin/cos
        # argument beyond 1e5) as a SystemError: raise it as the numpy definition does
        if isinstance(error.__cause__, ValueError):
            raise ValueError(f"{error.__cause__} (an episode diverged)") from error.__cause__
        raise
    if kept:
        longest = int(out["end_step"].max())
        for i, name in enumerate(("x", "x_dot", "phi", "phi_dot")):
            out[name] = np.ascontiguousarray(state[:longest, i])
        out.update({name: array[:longest] for name, array in trace.items()})
    return out


def warm_up() -> None:
    """Compile (or load from the cache) every kernel with the argument types lonlib passes."""
    fc = np.array(
        [9.8, 1.0, 0.1, 0.5, 5e-4, 2e-6, 0.02, 1.0, 0.02, 0.2, 2.0, 2.4, 2.0, 15.7, 0.0, -5.0]
    )
    ic = np.array([1, 1, 3, 0, 2, 0, 0], dtype=np.int64)
    sizes = np.array([10, 2, 1], dtype=np.int64)
    thetas = np.full((1, 25), 0.1)
    start = tuple(np.zeros((1, 1)) for _ in range(4))
    rollout_actors(fc, ic, sizes, thetas, np.zeros(1, dtype=np.int64), start, 1)
    rollout_actors(fc, ic, sizes, thetas, np.zeros(1, dtype=np.int64), start, 0)
    x, x_dot, phi, phi_dot = (np.zeros((1, 1)) for _ in range(4))
    observe_batch(fc, ic, x, x_dot, phi, phi_dot, np.zeros((1, 10)))
    step_batch(
        fc, ic, x, x_dot, phi, phi_dot, np.zeros(1, dtype=np.int64), np.zeros((1, 3)),
        np.zeros(1, dtype=np.int8), np.full((1, 1), 0.5), np.zeros(1), np.zeros(1),
        np.zeros((1, 1), dtype=np.bool_), np.zeros(1, dtype=np.bool_),
        np.zeros(1, dtype=np.bool_), np.zeros(1, dtype=np.int8),
    )  # fmt: skip
