"""How a :class:`~lonlib.config.pendulum.PendulumConfig` reaches the compiled kernels: two small
runtime arrays (:func:`pack`), so that one compilation serves every configuration, number of
carts and batch. numba-free; :mod:`lonlib.task.kernels` reads the indices below."""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from lonlib.util import portable_math

__all__ = ["pack"]

# Layout of the float array ``fc`` and the integer array ``ic`` (:func:`pack`).
(
    F_GRAVITY,
    F_CART_MASS,
    F_POLE_MASS,
    F_POLE_HALF_LENGTH,
    F_CART_FRICTION,
    F_HINGE_FRICTION,
    F_DT,
    F_MOTOR_GAIN,
    F_MOTOR_TAU,
    F_CART_WIDTH,
    F_TETHER,
    F_TRACK_HALF,
    F_VELOCITY_RANGE,
    F_ANGULAR_VELOCITY_RANGE,
    F_COS_UPRIGHT,
    F_PENALTY,
) = range(16)
I_N_CARTS, I_SUBSTEPS, I_STEPS, I_INTEGRATOR_EULER, I_MOTOR, I_FITNESS_MEAN, I_REWARD = range(7)
MOTOR_FORCE, MOTOR_ACCELERATION, MOTOR_VELOCITY = range(3)
REWARD_HEIGHT, REWARD_SLOW_HEIGHT, REWARD_HEIGHT_PRODUCT, REWARD_UPRIGHT = range(4)
_MOTORS = {"force": MOTOR_FORCE, "acceleration": MOTOR_ACCELERATION, "velocity": MOTOR_VELOCITY}
_REWARDS = {
    "height": REWARD_HEIGHT,
    "slow-height": REWARD_SLOW_HEIGHT,
    "height-product": REWARD_HEIGHT_PRODUCT,
    "upright": REWARD_UPRIGHT,
}


@functools.lru_cache(maxsize=64)
def pack(config: Any) -> tuple[np.ndarray, np.ndarray]:
    """``(fc, ic)``: a :class:`~lonlib.config.pendulum.PendulumConfig` as the kernels read it
    (float64 and int64 arrays, the derived values computed as the numpy definition does)."""
    fc = np.empty(16)
    fc[F_GRAVITY] = config.gravity
    fc[F_CART_MASS] = config.cart_mass
    fc[F_POLE_MASS] = config.pole_mass
    fc[F_POLE_HALF_LENGTH] = config.pole_half_length
    fc[F_CART_FRICTION] = config.cart_friction
    fc[F_HINGE_FRICTION] = config.hinge_friction
    fc[F_DT] = config.dt
    fc[F_MOTOR_GAIN] = config.motor_gain
    fc[F_MOTOR_TAU] = config.motor_tau
    fc[F_CART_WIDTH] = config.cart_width
    fc[F_TETHER] = config.tether_length
    fc[F_TRACK_HALF] = config.track_half_length
    fc[F_VELOCITY_RANGE] = config.velocity_range
    fc[F_ANGULAR_VELOCITY_RANGE] = config.angular_velocity_range
    fc[F_COS_UPRIGHT] = float(portable_math.cos(np.float64(config.upright_angle)))
    fc[F_PENALTY] = config.termination_penalty
    ic = np.array(
        [
            config.n_carts,
            config.substeps,
            config.steps,
            config.integrator == "euler",
            _MOTORS[config.motor],
            config.fitness_mode == "mean",
            _REWARDS[config.reward],
        ],
        dtype=np.int64,
    )
    fc.flags.writeable = False
    ic.flags.writeable = False
    return fc, ic
