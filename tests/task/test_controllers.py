"""Reference controllers: what zero effort and a hand-made swing-up reach."""

import math

import numpy as np
import pytest

from lonlib.config import PendulumConfig
from lonlib.task.controllers import SwingUpBalanceController, decode_sensors, zero_controller
from lonlib.task.pendulum import CoupledPendulums, EndReason, sensors, wrap_angle
from lonlib.task.rollout import evaluate


@pytest.mark.parametrize("n_carts", [1, 2])
def test_zero_controller_scores_zero_and_survives(n_carts):
    cfg = PendulumConfig(n_carts=n_carts)
    result = evaluate(zero_controller(cfg), cfg)
    assert result.fitness[0] == 0.0
    assert result.end_reason[0] == EndReason.STEP_LIMIT


@pytest.mark.parametrize("n_carts", [1, 2])
def test_swing_up_controller_keeps_rods_upright_most_of_the_episode(n_carts):
    cfg = PendulumConfig(n_carts=n_carts)
    result = evaluate(SwingUpBalanceController(cfg), cfg)
    assert result.fitness[0] > 0.75
    assert result.end_reason[0] == EndReason.STEP_LIMIT


def test_swing_up_works_in_acceleration_motor_mode():
    cfg = PendulumConfig(n_carts=1, motor="acceleration")
    assert evaluate(SwingUpBalanceController(cfg), cfg).fitness[0] > 0.5


def test_swing_up_balances_one_cart_under_the_velocity_motor_and_semi_implicit_euler():
    cfg = PendulumConfig(n_carts=1, motor="velocity", motor_tau=0.02, integrator="semi-implicit")
    sim, controller = CoupledPendulums(cfg), SwingUpBalanceController(cfg)
    angle, speed = [], []
    while not sim.done.all():
        sim.step(controller(sim.observe()))
        angle.append(wrap_angle(sim.phi)[0, 0])
        speed.append(sim.phi_dot[0, 0])
    assert sim.end_reason[0] == EndReason.STEP_LIMIT and sim.fitness[0] > 0.9
    # balanced, not spinning: the second half of the episode is still and upright
    assert np.abs(angle[1000:]).max() < 0.05 and np.abs(speed[1000:]).max() < 0.1


def test_decode_sensors_inverts_table_one_inside_the_ranges():
    cfg = PendulumConfig(n_carts=2)
    rng = np.random.default_rng(0)
    phi = rng.uniform(0, 2 * math.pi, size=(50, 2))
    v = rng.uniform(-2, 2, size=(50, 2))
    w = rng.uniform(-5 * math.pi, 5 * math.pi, size=(50, 2))
    x = np.tile(cfg.initial_positions(), (50, 1))
    decoded = decode_sensors(cfg, sensors(cfg, x, v, phi, w))
    theta = np.where(phi > math.pi, phi - 2 * math.pi, phi)
    np.testing.assert_allclose(decoded.theta, theta, atol=1e-9)
    np.testing.assert_allclose(decoded.x_dot, v, atol=1e-12)
    np.testing.assert_allclose(decoded.theta_dot, w, atol=1e-9)
