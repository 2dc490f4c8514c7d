"""Physics, sensors, termination, batching and configuration of the simulator."""

import math

import numpy as np
import pytest

from lonlib.config import PendulumConfig
from lonlib.config.pendulum import STEP_CAP
from lonlib.task.pendulum import (
    CoupledPendulums,
    EndReason,
    motor_command,
    sensors,
    total_energy,
    wrap_angle,
)
from lonlib.task.rollout import evaluate

FRICTIONLESS = {"cart_friction": 0.0, "hinge_friction": 0.0}


def free_drift(quantity, substeps: int, integrator: str = "euler") -> float:
    """Largest change of ``quantity(cfg, sim)`` for a free (frictionless, unpushed) cart and
    swinging rod over 500 steps (the force motor: only it leaves the cart free)."""
    cfg = PendulumConfig(
        n_carts=1,
        motor="force",
        substeps=substeps,
        integrator=integrator,
        track_half_length_base=100.0,
        **FRICTIONLESS,
    )
    sim = CoupledPendulums(cfg)
    sim.x_dot[:], sim.phi[:], sim.phi_dot[:] = 0.3, 2.0, 1.5
    start, drift = quantity(cfg, sim), 0.0
    for _ in range(500):
        sim.step(np.full((1, 1), 0.5))
        drift = max(drift, float(np.abs(quantity(cfg, sim) - start).max()))
    assert not sim.done.any()
    return drift


def energy_drift(substeps: int, integrator: str = "euler") -> float:
    """Largest change of the mechanical energy of a free cart and rod."""
    return free_drift(
        lambda cfg, sim: total_energy(cfg, sim.x_dot, sim.phi, sim.phi_dot), substeps, integrator
    )


def test_zero_input_frictionless_energy_within_euler_bound_that_shrinks_with_substeps():
    # Explicit Euler's global error over a fixed horizon is O(h): bound it by C h with
    # h = dt / substeps (C = 50 J/s over these 10 s), and ten times the substeps must cut
    # the drift at least five-fold.
    drifts = {s: energy_drift(s) for s in (1, 10, 100)}
    for substeps, drift in drifts.items():
        assert drift < 50.0 * 0.02 / substeps
    assert drifts[10] < drifts[1] / 5
    assert drifts[100] < drifts[10] / 5


def test_semi_implicit_integrator_also_converges():
    assert energy_drift(10, "semi-implicit") < energy_drift(1, "semi-implicit")


def test_energy_is_not_conserved_with_friction():
    cfg = PendulumConfig(n_carts=1, cart_friction=0.0, hinge_friction=0.05, substeps=50)
    sim = CoupledPendulums(cfg)
    sim.phi[:], sim.phi_dot[:] = 2.0, 0.0
    e0 = total_energy(cfg, sim.x_dot, sim.phi, sim.phi_dot)
    for _ in range(300):
        sim.step(np.full((1, 1), 0.5))
    assert total_energy(cfg, sim.x_dot, sim.phi, sim.phi_dot)[0, 0] < e0[0, 0] - 0.01


def test_hinge_friction_leaves_a_rod_less_energy_than_no_friction():
    # The same unpushed, cart-frictionless swing with and without hinge friction: the run
    # with friction must end with less energy; a friction term of the wrong sign pumps
    # energy in and ends with more.
    def final_energy(hinge_friction: float) -> float:
        cfg = PendulumConfig(
            n_carts=1, motor="force", cart_friction=0.0, hinge_friction=hinge_friction, substeps=50
        )
        sim = CoupledPendulums(cfg)
        sim.phi[:], sim.phi_dot[:] = math.pi - 0.5, 0.0
        for _ in range(300):
            sim.step(np.zeros((1, 1)))
        return float(total_energy(cfg, sim.x_dot, sim.phi, sim.phi_dot)[0, 0])

    assert final_energy(0.05) < final_energy(0.0) - 0.01


def one_cart_sensors(phi=math.pi, x=0.0, v=0.0, w=0.0):
    cfg = PendulumConfig(n_carts=1)
    arr = lambda value: np.array([[value]], dtype=float)  # noqa: E731
    return sensors(cfg, arr(x), arr(v), arr(phi), arr(w))[0]


@pytest.mark.parametrize(
    ("phi", "expected"),
    [
        (0.0, [1, 0, 0, 0]),
        (math.pi / 4, [0.5, 0, 0, 0]),
        (math.pi / 2, [0, 0, 1, 0]),
        (3 * math.pi / 4, [0, 0, 0.5, 0]),
        (math.pi, [0, 0, 0, 0]),
        (5 * math.pi / 4, [0, 0, 0, 0.5]),
        (3 * math.pi / 2 - 1e-9, [0, 0, 0, 1]),
        (3 * math.pi / 2, [0, 0, 0, 0]),
        (7 * math.pi / 4, [0, 0.5, 0, 0]),
        (2 * math.pi - 1e-9, [0, 1, 0, 0]),
    ],
)
def test_angle_sensors_at_every_quadrant_edge(phi, expected):
    np.testing.assert_allclose(one_cart_sensors(phi=phi)[:4], expected, atol=1e-8)


@pytest.mark.parametrize(
    ("v", "w", "expected"),
    [
        (-2.0, 0.0, [1, 0, 0, 0]),
        (-7.0, 0.0, [1, 0, 0, 0]),  # saturates
        (1.0, 0.0, [0, 0.5, 0, 0]),
        (2.0, 0.0, [0, 1, 0, 0]),
        (0.0, -5 * math.pi, [0, 0, 1, 0]),
        (0.0, 2.5 * math.pi, [0, 0, 0, 0.5]),
        (0.0, 40.0, [0, 0, 0, 1]),  # saturates
    ],
)
def test_velocity_sensors_and_saturation(v, w, expected):
    np.testing.assert_allclose(one_cart_sensors(v=v, w=w)[6:], expected, atol=1e-12)


def test_proximity_to_neighbour_and_track_end():
    cfg = PendulumConfig(n_carts=2)
    half = cfg.track_half_length
    zeros = np.zeros((3, 2))
    x = np.array(
        [
            [-0.1, 0.1],  # neighbours touching (distance = width)
            [-1.0, 1.0],  # neighbours at the tether length
            [-half + 0.1, -half + 1.0],  # left cart touching the track end
        ]
    )
    s = sensors(cfg, x, zeros, np.full((3, 2), np.pi), zeros).reshape(3, 2, 10)
    assert s[0, 0, 5] == pytest.approx(1.0) and s[0, 1, 4] == pytest.approx(1.0)
    assert s[1, 0, 5] == pytest.approx(0.0) and s[1, 1, 4] == pytest.approx(0.0)
    assert s[2, 0, 4] == pytest.approx(1.0)  # track end reads like a touching neighbour
    mid = (cfg.tether_length - 0.9) / (cfg.tether_length - cfg.cart_width)
    assert s[2, 0, 5] == pytest.approx(mid)
    assert s[0, 0, 4] == 0.0  # the far track end is out of range


def test_action_conversion_matches_paper():
    np.testing.assert_allclose(
        motor_command(np.array([0.0, 0.25, 0.5, 0.75, 1.0])), [2.0, 1.0, 0.0, -1.0, -2.0]
    )
    # a > 0.5 pushes right: the cart accelerates in +x
    cfg = PendulumConfig(n_carts=1)
    sim = CoupledPendulums(cfg)
    for _ in range(3):
        sim.step(np.ones((1, 1)))
    assert sim.x_dot[0, 0] > 0


def constant_velocity_sim(n, x, x_dot):
    cfg = PendulumConfig(n_carts=n, motor="acceleration", **FRICTIONLESS)
    sim = CoupledPendulums(cfg)
    sim.x[:], sim.x_dot[:] = x, x_dot
    return sim


@pytest.mark.parametrize(
    ("n", "x", "x_dot", "reason", "step"),
    [
        # gap 1 - 0.036 k drops below the 0.2 m cart width at k = 23
        (2, [-0.5, 0.5], [0.9, -0.9], EndReason.COLLISION, 23),
        # gap 1 + 0.036 k passes the 2.0 m tether at k = 28
        (2, [-0.5, 0.5], [-0.9, 0.9], EndReason.TETHER, 28),
        # the edge 0.018 k + 0.1 passes the 2.4 m track end at k = 128
        (1, [0.0], [0.9], EndReason.BOUNDARY, 128),
    ],
)
def test_each_termination_rule_fires_at_its_step(n, x, x_dot, reason, step):
    sim = constant_velocity_sim(n, x, x_dot)
    for k in range(1, step + 5):
        result = sim.step(np.full((1, n), 0.5))
        if k < step:
            assert not result.terminated[0], k
        elif k == step:
            assert result.terminated[0] and not result.truncated[0]
            assert result.end_reason[0] == reason
            frozen = sim.x.copy()
        else:
            assert not result.terminated[0] and result.reward[0] == 0.0
            np.testing.assert_array_equal(sim.x, frozen)
    assert sim.end_reason[0] == reason and sim.step_count[0] == step


def test_step_limit_truncates():
    cfg = PendulumConfig(n_carts=1, steps=37)
    sim = CoupledPendulums(cfg)
    for k in range(1, 38):
        result = sim.step(np.full((1, 1), 0.5))
        assert result.truncated[0] == (k == 37)
    assert sim.end_reason[0] == EndReason.STEP_LIMIT and not result.terminated[0]


def linear_weights(seed, n, batch):
    return np.random.default_rng(seed).normal(0, 3, size=(batch, 10 * n, n))


def linear_policy(seed, n, batch, weights=None):
    """Row b of the batch is driven by its own random linear-sigmoid policy."""
    weights = linear_weights(seed, n, batch) if weights is None else weights
    return lambda obs: 1 / (1 + np.exp(-np.einsum("bi,bij->bj", obs, weights)))


def trajectory(cfg, policy, batch, seed=None, steps=300):
    sim = CoupledPendulums(cfg, batch, seed)
    states = []
    for _ in range(steps):
        sim.step(policy(sim.observe()))
        states.append(np.stack([sim.x, sim.x_dot, sim.phi, sim.phi_dot]))
    return np.stack(states), sim


def test_batch_equals_single_runs():
    cfg = PendulumConfig(n_carts=2)
    batch = 5
    policy = linear_policy(3, 2, batch)
    together, sim = trajectory(cfg, policy, batch)
    assert len(set(sim.end_reason.tolist())) > 1 or sim.done.any()
    weights = linear_weights(3, 2, batch)
    for b in range(batch):
        alone, single = trajectory(cfg, linear_policy(0, 2, 1, weights[b : b + 1]), 1)
        np.testing.assert_array_equal(alone[:, :, 0], together[:, :, b])
        assert single.fitness[0] == sim.fitness[b]
        assert single.end_reason[0] == sim.end_reason[b]


def test_same_seed_same_trajectory_and_different_seed_differs():
    cfg = PendulumConfig(n_carts=2, initial_noise=0.05)
    policy = linear_policy(1, 2, 3)
    a, _ = trajectory(cfg, policy, 3, seed=11, steps=50)
    b, _ = trajectory(cfg, policy, 3, seed=11, steps=50)
    c, _ = trajectory(cfg, policy, 3, seed=12, steps=50)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_fitness_modes_all_versus_mean():
    # one rod held upright, one hanging, no motion: "all" scores 0, "mean" scores 1/2
    for mode, expected in (("all", 0.0), ("mean", 0.5)):
        cfg = PendulumConfig(
            n_carts=2,
            fitness_mode=mode,
            steps=10,
            motor="acceleration",
            gravity=1e-9,
            **FRICTIONLESS,
        )
        sim = CoupledPendulums(cfg)
        sim.phi[:] = [[0.0, np.pi]]
        while not sim.done.all():
            sim.step(np.full((1, 2), 0.5))
        assert sim.fitness[0] == pytest.approx(expected)


def test_upright_reward_is_the_fitness_increment_and_height_reward_is_bounded():
    cfg = PendulumConfig(n_carts=1, reward="upright", steps=20, gravity=1e-9)
    sim = CoupledPendulums(cfg)
    sim.phi[:] = 0.1
    total = sum(sim.step(np.full((1, 1), 0.5)).reward[0] for _ in range(20))
    assert total == pytest.approx(sim.fitness[0]) and total == pytest.approx(1.0)
    cfg = PendulumConfig(n_carts=1)
    sim = CoupledPendulums(cfg)
    sim.phi[:] = 0.0
    assert sim.step(np.full((1, 1), 0.5)).reward[0] == pytest.approx(1.0, abs=1e-3)


def test_wrap_angle():
    np.testing.assert_allclose(
        wrap_angle(np.array([0.0, np.pi, 1.5 * np.pi, -np.pi])), [0.0, np.pi, -0.5 * np.pi, np.pi]
    )


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("n_carts", 0),
        ("n_carts", 6),
        ("n_carts", 2.0),
        ("steps", STEP_CAP + 1),
        ("steps", 0),
        ("substeps", 0),
        ("gravity", 0.0),
        ("cart_mass", -1.0),
        ("pole_mass", 0.0),
        ("pole_half_length", -0.5),
        ("cart_friction", -0.1),
        ("hinge_friction", float("nan")),
        ("dt", 0.0),
        ("dt", float("inf")),
        ("motor_gain", 0.0),
        ("motor_tau", 0.0),
        ("motor_tau", 10.5),
        ("cart_width", 0.0),
        ("tether_length", 0.1),
        ("initial_spacing", 3.0),
        ("track_half_length_base", -1.0),
        ("track_half_length_per_cart", -0.1),
        ("velocity_range", 0.0),
        ("angular_velocity_range", -1.0),
        ("upright_angle", 0.0),
        ("upright_angle", 4.0),
        ("integrator", "rk4"),
        ("motor", "torque"),
        ("fitness_mode", "sum"),
        ("reward", "sparse"),
        ("termination_penalty", 1.0),
        ("initial_noise", -0.1),
        ("initial_noise", 0.9),
        ("initial_angle", 7.0),
    ],
)
def test_every_invalid_field_is_refused_by_name(field, value):
    with pytest.raises(ValueError, match=field):
        PendulumConfig(**{field: value})


def test_unknown_key_is_refused_by_name():
    with pytest.raises(ValueError, match="velocityy"):
        PendulumConfig.from_mapping({"n_carts": 2, "velocityy": 1.0})
    assert PendulumConfig.from_mapping({"n_carts": 3}).n_carts == 3


def test_track_grows_with_carts_and_all_start_positions_are_valid():
    for n in range(1, 6):
        cfg = PendulumConfig(n_carts=n)
        assert cfg.track_half_length == pytest.approx(2.4 + 0.55 * (n - 1))
        sim = CoupledPendulums(cfg)
        assert (sim._termination_reason() == EndReason.RUNNING).all()
        assert sim.observe().shape == (1, 10 * n)


def test_evaluate_reports_fitness_and_reason_per_environment():
    cfg = PendulumConfig(n_carts=2, steps=200)
    full_push = evaluate(lambda o: np.ones((len(o), 2)), cfg, batch_size=3)
    assert (full_push.end_reason == EndReason.BOUNDARY).all()
    assert (full_push.fitness == 0).all() and (full_push.steps < 200).all()


@pytest.mark.parametrize(("integrator", "grows"), [("euler", True), ("semi-implicit", False)])
def test_explicit_euler_swings_a_hanging_rod_up_and_semi_implicit_does_not(integrator, grows):
    # The documented property of the default integrator: explicit Euler at dt = 0.02 s feeds
    # energy into a swinging rod; symplectic Euler keeps a hanging rod's swing bounded.
    cfg = PendulumConfig(n_carts=1, initial_noise=0.02, integrator=integrator, steps=2000)
    sim = CoupledPendulums(cfg, 16, seed=0)
    start = float((np.pi - np.abs(wrap_angle(sim.phi))).max())
    peak = 0.0
    while not sim.done.all():
        sim.step(np.full((16, 1), 0.5))
        peak = max(peak, float((np.pi - np.abs(wrap_angle(sim.phi))).max()))
    assert (peak > 5 * start) == grows, (start, peak)
    if not grows:
        assert (sim.fitness == 0).all()


def test_default_physics_is_the_calibrated_velocity_motor_with_semi_implicit_euler():
    config = PendulumConfig()
    assert (config.motor, config.integrator, config.motor_tau) == (
        "velocity",
        "semi-implicit",
        0.02,
    )


def horizontal_momentum(cfg, sim):
    """(M + m) x_dot + m l cos(phi) phi_dot of each cart and rod."""
    m, l = cfg.pole_mass, cfg.pole_half_length
    return (cfg.cart_mass + m) * sim.x_dot + m * l * np.cos(sim.phi) * sim.phi_dot


@pytest.mark.parametrize("v0", [1.0, -1.0])
def test_a_coasting_cart_slows_down_under_coulomb_friction(v0):
    # Barto's cart friction mu_c sgn(x_dot) is the only horizontal force on an unpushed
    # cart and rod: their momentum falls at exactly mu_c against the motion.
    cfg = PendulumConfig(
        n_carts=1, motor="force", cart_friction=0.05, hinge_friction=0.0, substeps=10
    )
    sim = CoupledPendulums(cfg)
    sim.x_dot[:] = v0
    p0 = horizontal_momentum(cfg, sim)[0, 0]
    for _ in range(50):
        sim.step(np.full((1, 1), 0.5))
    lost = p0 - horizontal_momentum(cfg, sim)[0, 0]
    assert lost == pytest.approx(np.sign(v0) * 50 * cfg.dt * 0.05, rel=1e-3)
    assert abs(sim.x_dot[0, 0]) < abs(v0)


def momentum_drift(substeps: int, integrator: str) -> float:
    """Largest change of the horizontal momentum of a free cart and rod."""
    return free_drift(horizontal_momentum, substeps, integrator)


@pytest.mark.parametrize("integrator", ["euler", "semi-implicit"])
def test_horizontal_momentum_is_conserved_up_to_the_integrators_error(integrator):
    drifts = {s: momentum_drift(s, integrator) for s in (1, 10)}
    assert drifts[1] < 0.05  # the rod's own momentum swings by ~0.15 kg m/s
    assert drifts[10] < drifts[1] / 5


@pytest.mark.parametrize("motor", ["force", "acceleration"])
def test_a_hanging_rods_tip_lags_behind_an_accelerating_cart(motor):
    cfg = PendulumConfig(n_carts=1, motor=motor, **FRICTIONLESS)
    sim = CoupledPendulums(cfg)
    for _ in range(10):
        sim.step(np.ones((1, 1)))  # full push to the right
    assert sim.x_dot[0, 0] > 0
    assert np.sin(sim.phi[0, 0]) < -1e-3  # tip (x + l sin phi) behind the cart, to the left
    assert sim.phi_dot[0, 0] > 0


def test_a_free_rod_on_a_cart_at_constant_speed_keeps_its_energy_in_acceleration_mode():
    cfg = PendulumConfig(
        n_carts=1, motor="acceleration", integrator="semi-implicit", substeps=10, **FRICTIONLESS
    )
    m, l, g = cfg.pole_mass, cfg.pole_half_length, cfg.gravity
    sim = CoupledPendulums(cfg)
    sim.x_dot[:], sim.phi[:] = 0.5, 2.0

    def rod_energy():
        return (2 / 3) * m * l**2 * sim.phi_dot**2 + m * g * l * np.cos(sim.phi)

    e0 = rod_energy()
    for _ in range(300):
        sim.step(np.full((1, 1), 0.5))  # zero command: zero acceleration
        assert abs(rod_energy() - e0)[0, 0] < 5e-3 * m * g * l  # bounded, symplectic
    assert sim.x_dot[0, 0] == 0.5


def test_an_ended_episode_scores_and_earns_nothing_more():
    # Rods start upright and "upright" is anything but exactly hanging: env 0 pushes into
    # the track end and stops scoring there; env 1 never pushes and scores every step.
    cfg = PendulumConfig(n_carts=1, steps=100, initial_angle=0.0, upright_angle=math.pi)
    sim = CoupledPendulums(cfg, 2)
    rewards = []
    while not sim.done.all():
        rewards.append(sim.step(np.array([[1.0], [0.5]])).reward)
    ended_at = int(sim.step_count[0])
    assert sim.end_reason.tolist() == [EndReason.BOUNDARY, EndReason.STEP_LIMIT]
    assert ended_at < 100 and sim.fitness[0] == pytest.approx(ended_at / 100)
    assert sim.fitness[1] == 1.0
    assert all(r[0] == 0 for r in rewards[ended_at:])


def test_the_termination_penalty_falls_on_a_true_end_only():
    cfg = PendulumConfig(n_carts=1, steps=150, termination_penalty=-5.0)
    sim = CoupledPendulums(cfg, 2)
    last = [None, None]
    while not sim.done.all():
        running = ~sim.done
        out = sim.step(np.array([[1.0], [0.5]]))  # env 0 hits the track end, env 1 times out
        height = 0.5 * (1.0 + np.cos(sim.phi)).mean(axis=1)
        for i in np.flatnonzero(running & (out.terminated | out.truncated)):
            last[i] = (out.reward[i], height[i], bool(out.terminated[i]))
    assert last[0][2] and last[0][0] == pytest.approx(last[0][1] - 5.0)
    assert not last[1][2] and last[1][0] == pytest.approx(last[1][1])


# ---------------------------------------------------------------- velocity motor
def velocity_sim(tau=0.1, substeps=1, integrator="semi-implicit", **changes):
    cfg = PendulumConfig(
        n_carts=1,
        motor="velocity",
        motor_tau=tau,
        substeps=substeps,
        integrator=integrator,
        track_half_length_base=100.0,
        **{**FRICTIONLESS, **changes},
    )
    return CoupledPendulums(cfg)


def speed_response(sim, action, steps):
    speeds = []
    for _ in range(steps):
        sim.step(np.full((1, 1), action))
        speeds.append(sim.x_dot[0, 0])
    return np.array(speeds)


def test_velocity_motor_reaches_the_commanded_speed_with_the_first_order_lag():
    tau, target = 0.1, 2.0  # a = 1: full command to the right, 2 m/s
    k = np.arange(1, 51)
    # one Euler step per control step: exactly the discrete first-order lag
    speeds = speed_response(velocity_sim(tau), 1.0, 50)
    np.testing.assert_allclose(speeds, target * (1 - (1 - 0.02 / tau) ** k), rtol=1e-12)
    # with fine substeps: the analytic response 1 - exp(-t / tau) (63 % of the target at tau)
    speeds = speed_response(velocity_sim(tau, substeps=100), 1.0, 50)
    analytic = target * (1 - np.exp(-k * 0.02 / tau))
    assert np.abs(speeds - analytic).max() < 0.005
    assert speeds[4] == pytest.approx(target * (1 - math.exp(-1)), abs=0.005)
    # tau = dt is an ideal speed servo: the command is reached in one step, either integrator
    for integrator in ("euler", "semi-implicit"):
        np.testing.assert_allclose(
            speed_response(velocity_sim(0.02, integrator=integrator), 0.25, 3), -1.0
        )


def test_velocity_motor_cart_commanded_to_zero_stays_put_whatever_its_rod_does():
    sim = velocity_sim(tau=0.1)
    sim.phi[:], sim.phi_dot[:] = 2.0, 3.0
    for _ in range(300):
        sim.step(np.full((1, 1), 0.5))
    assert sim.x[0, 0] == 0.0 and sim.x_dot[0, 0] == 0.0
    assert abs(sim.phi_dot[0, 0]) > 0.5  # the rod kept swinging
    # a moving cart commanded to 0 stops and then stays
    sim = velocity_sim(tau=0.1)
    sim.x_dot[:] = 1.5
    speeds = speed_response(sim, 0.5, 200)
    assert (np.diff(speeds) <= 0).all() and abs(speeds[-1]) < 1e-15
    # it glides v (tau - h) (the discrete lag's sum; v tau in continuous time), then stays
    glide = sim.x[0, 0]
    assert glide == pytest.approx(1.5 * (0.1 - 0.02))
    speed_response(sim, 0.5, 100)
    assert sim.x[0, 0] == pytest.approx(glide, abs=1e-15)


@pytest.mark.parametrize(("start", "integrator"), [(math.pi, "euler"), (0.0, "semi-implicit")])
def test_rod_swings_backwards_when_the_cart_speeds_up(start, integrator):
    # A cart stepping to the right throws its rod's tip to the left (sin(phi) < 0), hanging
    # or upright, and the opposite command mirrors it.
    for action, side in ((1.0, -1.0), (0.0, 1.0)):
        sim = velocity_sim(tau=0.05, integrator=integrator)
        sim.phi[:] = start
        for _ in range(5):
            sim.step(np.full((1, 1), action))
        assert np.sign(sim.x_dot[0, 0]) == -side
        assert np.sign(np.sin(sim.phi[0, 0])) == side


def rod_energy_drift(integrator):
    """Energy drift of a swinging rod on a cart driven at a constant 1 m/s: first and last
    500 of 2000 steps."""
    sim = velocity_sim(tau=0.02, integrator=integrator)
    cfg = sim.config
    m, l, g = cfg.pole_mass, cfg.pole_half_length, cfg.gravity
    sim.x_dot[:], sim.phi[:] = 1.0, 2.0
    drift = []
    for _ in range(2000):
        energy = (2 / 3) * m * l**2 * sim.phi_dot**2 + m * g * l * np.cos(sim.phi)
        drift.append(energy[0, 0])
        sim.step(np.full((1, 1), 0.75))  # u = -1: 1 m/s to the right, the speed it has
    assert sim.x_dot[0, 0] == 1.0 and sim.end_reason[0] != EndReason.BOUNDARY
    drift = np.abs(np.array(drift) - drift[0])
    return drift[:500].max(), drift[-500:].max()


def test_rod_energy_on_a_cart_at_constant_speed_stays_within_the_semi_implicit_bound():
    # At constant speed the cart's frame is inertial: the rod's energy about its hinge is
    # conserved. Symplectic Euler keeps the error O(h) (bounded, no trend); explicit Euler
    # lets it grow.
    early, late = rod_energy_drift("semi-implicit")
    assert early < 1.0 * 0.02 and late < 1.1 * early
    early, late = rod_energy_drift("euler")
    assert late > 2 * early


def test_velocity_motor_tau_must_not_be_shorter_than_the_integration_step():
    PendulumConfig(motor="velocity", motor_tau=0.02)
    PendulumConfig(motor="velocity", motor_tau=0.005, substeps=4)
    PendulumConfig(motor="force", motor_tau=0.001)  # unused by the other motors
    for changes in ({"motor_tau": 0.01}, {"motor_tau": 0.004, "substeps": 4}):
        with pytest.raises(ValueError, match="motor_tau"):
            PendulumConfig(motor="velocity", **changes)


def test_slow_height_reward_prefers_a_slow_upright_rod_to_a_spinning_one():
    def reward(phi_dot, kind):
        cfg = PendulumConfig(n_carts=1, reward=kind, gravity=1e-9, **FRICTIONLESS)
        sim = CoupledPendulums(cfg)
        sim.phi[:], sim.phi_dot[:] = 0.0, phi_dot
        return sim.step(np.full((1, 1), 0.5)).reward[0]

    assert reward(0.0, "slow-height") == pytest.approx(reward(0.0, "height"))
    assert reward(0.0, "slow-height") > reward(8.0, "slow-height") > 0.0
    assert reward(-8.0, "slow-height") == pytest.approx(reward(8.0, "slow-height"), rel=1e-3)
    assert reward(20.0, "slow-height") == 0.0 and reward(20.0, "height") > 0.5
