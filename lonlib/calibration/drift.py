"""The integrators' drift, beside the study's grid (``drift.csv``): each integrator's energy
and momentum error in a short motor-off, friction-off rollout of one cart (force model: the
cart is free, so the cart-and-rod energy and horizontal momentum are both conserved by the
continuous equations), run by the one rollout (:func:`lonlib.task.rollout.run_policy`)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pandas as pd

from lonlib.config import PendulumConfig
from lonlib.config.calibration import INTEGRATORS
from lonlib.task.pendulum import total_energy, wrap_angle
from lonlib.task.rollout import run_policy
from lonlib.util import portable_math


def _motor_off(observation: np.ndarray) -> np.ndarray:
    """The constant policy of :func:`integrator_drift`: command 0.5, no force."""
    return np.full((len(observation), 1), 0.5)


def integrator_drift(env: PendulumConfig, steps: int = 2000, swing: float = 0.02) -> pd.DataFrame:
    """Energy and momentum drift of each integrator with the motor and friction off.

    One cart (force model, ``env``'s masses, rod and dt), the rod released ``swing`` rad from
    hanging, the cart at rest, ``steps`` control steps on an endless track, run by the one
    rollout (:func:`lonlib.task.rollout.run_policy`, traced) with a constant zero-force command.
    The continuous equations conserve the energy ``E`` and the horizontal momentum
    ``p = (M + m) x_dot + m l cos(phi) phi_dot``. Reports per integrator the largest
    ``|E - E0|`` [J] and ``|p - p0|`` [kg m/s], the final energy gain above the hanging rest
    relative to the start's, and the swing amplitude over the last tenth of the rollout
    relative to ``swing`` (1 = conserved; a rod that goes over the top reads ~pi / swing).
    """
    rows = []
    for integrator in INTEGRATORS:
        cfg = dataclasses.replace(
            env,
            n_carts=1,
            motor="force",
            integrator=integrator,
            cart_friction=0.0,
            hinge_friction=0.0,
            track_half_length_base=1e9,
            steps=steps,
            initial_noise=0.0,
            initial_angle=math.pi,
        )
        m, l, big_m = cfg.pole_mass, cfg.pole_half_length, cfg.cart_mass
        offsets = np.zeros((4, 1, 1))
        offsets[2] = -swing  # phi = pi - swing: released from rest
        trace = run_policy(_motor_off, cfg, offsets, trace=True).trace
        if trace is None:
            raise RuntimeError("the drift rollout kept no trace")
        # the start, then the state after every step, of the one episode: [steps + 1]
        x_dot = np.concatenate([[0.0], trace.x_dot[:, 0, 0]])
        phi = np.concatenate([[math.pi - swing], trace.phi[:, 0, 0]])
        phi_dot = np.concatenate([[0.0], trace.phi_dot[:, 0, 0]])
        if len(phi) != steps + 1:
            raise RuntimeError(f"the drift rollout ended after {len(phi) - 1} of {steps} steps")
        energy = total_energy(cfg, x_dot, phi, phi_dot)
        momentum = (big_m + m) * x_dot + m * l * portable_math.cos(phi) * phi_dot
        bottom = -m * cfg.gravity * l
        tail = phi[1 + steps - max(steps // 10, 1) :]
        rows.append(
            {
                "integrator": integrator,
                "steps": steps,
                "energy_drift": float(np.max(np.abs(energy[1:] - energy[0]))),
                "momentum_drift": float(np.max(np.abs(momentum[1:] - momentum[0]))),
                "energy_ratio": float((energy[-1] - bottom) / (energy[0] - bottom)),
                "amplitude_ratio": float(np.max(np.pi - np.abs(wrap_angle(tail)))) / swing,
            }
        )
    return pd.DataFrame(rows)


__all__ = ["integrator_drift"]
