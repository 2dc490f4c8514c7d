"""Reference controllers: what zero effort and what a good hand-made policy score.

Both are :data:`lonlib.task.pendulum.Policy` callables on the **normalised sensors** the networks
see (``[B, 10 n]`` -> ``[B, n]``), so their fitness is directly comparable with a trained
Actor's. :func:`decode_sensors` inverts Table I (exactly, inside the sensor ranges).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from lonlib.config import PendulumConfig
from lonlib.config.pendulum import SENSORS_PER_CART


@dataclass(frozen=True)
class DecodedSensors:
    """Per-cart physical quantities read back from normalised sensors (``[B, n]`` arrays)."""

    theta: np.ndarray  # rod angle from upright in (-pi, pi], 0 = upright (hanging reads 0 -> pi)
    theta_dot: np.ndarray  # rad/s, saturated at the sensor range
    x_dot: np.ndarray  # m/s, saturated at the sensor range
    proximity_left: np.ndarray  # in [0, 1], 1 = touching
    proximity_right: np.ndarray


def decode_sensors(config: PendulumConfig, observation: np.ndarray) -> DecodedSensors:
    """Invert Table I: angle, angular velocity, velocity and proximities per cart."""
    s = np.asarray(observation, dtype=np.float64).reshape(
        observation.shape[0], config.n_carts, SENSORS_PER_CART
    )
    s0, s1, s2, s3 = s[..., 0], s[..., 1], s[..., 2], s[..., 3]
    quadrant = np.select(
        [s0 > 0, s2 > 0, s3 > 0, s1 > 0], [1.0 - s0, 2.0 - s2, 2.0 + s3, 3.0 + s1], 2.0
    )
    phi = quadrant * 0.5 * np.pi
    theta = np.where(phi > np.pi, phi - 2 * np.pi, phi)
    return DecodedSensors(
        theta=theta,
        theta_dot=(s[..., 9] - s[..., 8]) * config.angular_velocity_range,
        x_dot=(s[..., 7] - s[..., 6]) * config.velocity_range,
        proximity_left=s[..., 4],
        proximity_right=s[..., 5],
    )


def zero_controller(config: PendulumConfig):
    """The policy that never pushes (``a = 0.5`` everywhere): fitness 0 from a hanging start."""
    n = config.n_carts

    def policy(observation: np.ndarray) -> np.ndarray:
        return np.full((observation.shape[0], n), 0.5)

    return policy


@dataclass(frozen=True)
class SwingUpGains:
    """Tuning of :class:`SwingUpBalanceController` (our values, see README)."""

    energy_gain: float = 10.0  # desired accel per (J * rad/s) of energy error
    velocity_damping: float = 3.0  # cart-velocity feedback while pumping [1/s]
    capture_angle: float = 0.6  # switch to the balance law inside this |theta| [rad]
    lqr_weights: tuple[float, float, float] = (20.0, 1.0, 2.0)  # theta, theta_dot, x_dot
    lqr_input_weight: float = 0.5
    centring_gain: float = 3.0  # accel per unit of (proximity right - proximity left) [m/s^2]
    proximity_guard: float = 0.85  # push away from a neighbour or track end closer than this


class SwingUpBalanceController:
    """Energy-pumping swing-up (Åström & Furuta 2000) with an LQR balance law, per cart.

    Works in cart-acceleration space: pumping asks ``x_ddot = k (E - E_up) theta_dot cos``;
    near upright an LQR on the linearised rod ``(theta, theta_dot, x_dot)`` takes over.
    The desired acceleration becomes a motor action through the exact inverse dynamics of
    the configured motor (force, acceleration, or the speed command ``x_dot + tau x_ddot``
    of the velocity servo) and is clipped to what the motor can do.
    It sees only the sensors, so cart position is known only near neighbours and track ends.
    """

    def __init__(self, config: PendulumConfig, gains: SwingUpGains | None = None) -> None:
        self.config = config
        self.gains = gains or SwingUpGains()
        l, g = config.pole_half_length, config.gravity
        # Linearised rod about upright with the cart acceleration as input.
        a = np.array([[0.0, 1.0, 0.0], [0.75 * g / l, 0.0, 0.0], [0.0, 0.0, 0.0]])
        b = np.array([[0.0], [-0.75 / l], [1.0]])
        q = np.diag(self.gains.lqr_weights)
        r = np.array([[self.gains.lqr_input_weight]])
        p = scipy.linalg.solve_continuous_are(a, b, q, r)
        self.lqr_gain = (np.linalg.solve(r, b.T @ p)).ravel()  # u = -K z
        # Centring holds each side's proximity at its starting value: 0 for a track end far
        # away, the initial spacing's reading for a neighbour (so neighbours keep their gap).
        neighbour = (config.tether_length - config.initial_spacing) / (
            config.tether_length - config.cart_width
        )
        inner = np.full(config.n_carts, neighbour)
        self._reference_left = np.where(np.arange(config.n_carts) == 0, 0.0, inner)
        self._reference_right = np.where(
            np.arange(config.n_carts) == config.n_carts - 1, 0.0, inner
        )

    def desired_acceleration(self, d: DecodedSensors) -> np.ndarray:
        """Cart acceleration [m/s^2] the law asks for, ``[B, n]``."""
        cfg, k = self.config, self.gains
        m, l, g = cfg.pole_mass, cfg.pole_half_length, cfg.gravity
        energy = (2.0 / 3.0) * m * l**2 * d.theta_dot**2 + m * g * l * np.cos(d.theta)
        drive = d.theta_dot * np.cos(d.theta)
        drive = np.where(drive == 0.0, -1e-3, drive)  # a nudge out of the resting hang
        centring = k.centring_gain * (
            (d.proximity_right - self._reference_right) - (d.proximity_left - self._reference_left)
        )
        pump = (
            k.energy_gain * (energy - m * g * l) * drive - k.velocity_damping * d.x_dot - centring
        )
        z = np.stack([d.theta, d.theta_dot, d.x_dot], axis=-1)
        balance = -(z @ self.lqr_gain)
        near_up = np.abs(d.theta) < k.capture_angle
        accel = np.where(near_up, balance, pump)
        guard = (d.proximity_right > k.proximity_guard).astype(float) - (
            d.proximity_left > k.proximity_guard
        )
        return np.where(guard != 0, -2.0 * guard, accel)

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        """Actions in [0, 1] for normalised sensors ``[B, 10 n]``."""
        cfg = self.config
        d = decode_sensors(cfg, observation)
        accel = self.desired_acceleration(d)
        if cfg.motor == "force":
            m, l, g = cfg.pole_mass, cfg.pole_half_length, cfg.gravity
            sin, cos = np.sin(d.theta), np.cos(d.theta)
            theta_ddot = 0.75 / l * (g * sin - accel * cos)
            drive = (cfg.cart_mass + m) * accel + m * l * (theta_ddot * cos - d.theta_dot**2 * sin)
        elif cfg.motor == "velocity":
            # x_ddot = (v_cmd - x_dot) / tau  =>  the speed to command for this acceleration
            drive = d.x_dot + cfg.motor_tau * accel
        else:
            drive = accel
        # drive = -gain * u and u = 2 - 4a  =>  a = (drive / gain + 2) / 4
        return np.clip((drive / cfg.motor_gain + 2.0) / 4.0, 0.0, 1.0)


__all__ = [
    "DecodedSensors",
    "SwingUpBalanceController",
    "SwingUpGains",
    "decode_sensors",
    "zero_controller",
]
