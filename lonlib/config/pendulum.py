"""The coupled inverted pendulums task's configuration (the paper's ``e``): every constant of
the physics, validated when it is made (the physics itself: :mod:`lonlib.task.pendulum`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lonlib.util.validation import check_choice, check_field_types, check_keys, check_range

SENSORS_PER_CART = 10
SENSOR_MAX = 127.0
MAX_CARTS = 5
MAX_MOTOR_TAU = 10.0  # [s]; a slower servo is not a motor any more
STEP_CAP = 3000  # paper: "the simulation spans a maximum of 3000 time steps"

_CHOICES = {
    "integrator": ("euler", "semi-implicit"),
    "motor": ("force", "acceleration", "velocity"),
    "fitness_mode": ("all", "mean"),
    "reward": ("height", "slow-height", "height-product", "upright"),
}


@dataclass(frozen=True)
class PendulumConfig:
    """Every constant of the coupled inverted pendulums task (the paper's ``e``).

    Paper values: ``n_carts`` range, the sensor ranges (2 m/s, 5 pi rad/s), the action
    conversion, the 3000-step cap. Everything else is our documented default (module
    docstring and README). Construction validates every field and raises ``ValueError``
    naming the field and its allowed range.
    """

    n_carts: int = 2
    """Carts on the track, 1 to 5 (the paper studies 1 and 2)."""
    gravity: float = 9.8
    """Gravitational acceleration, m/s^2 (classic cart-pole)."""
    cart_mass: float = 1.0
    """Mass of each cart, kg."""
    pole_mass: float = 0.1
    """Mass of each (uniform) rod, kg."""
    pole_half_length: float = 0.5
    """Half the length of each rod, m."""
    cart_friction: float = 0.0005
    """Friction coefficient between a cart and the track."""
    hinge_friction: float = 0.000002
    """Friction coefficient of each rod's hinge."""
    dt: float = 0.02
    """Seconds per control step (one action, one sensor reading)."""
    substeps: int = 1
    """Integration steps per control step (each ``dt / substeps`` s)."""
    integrator: str = "semi-implicit"
    """``semi-implicit`` (symplectic) Euler, the default, or explicit ``euler``."""
    motor: str = "velocity"
    """How an action moves a cart: ``velocity`` (a target speed reached with lag ``motor_tau``,
    the default), ``force`` or ``acceleration``."""
    motor_gain: float = 1.0
    """Scale of the motor command ``u`` in [-2, 2]: N, m/s^2 or m/s per unit."""
    motor_tau: float = 0.02
    """Time constant of the velocity motor's first-order lag, s."""
    cart_width: float = 0.2
    """Cart width, m: carts whose centres are closer than this collide."""
    tether_length: float = 2.0
    """Tether between neighbouring carts, m: farther apart, the chain breaks."""
    initial_spacing: float = 1.1
    """Distance between neighbouring carts at the start, m."""
    track_half_length_base: float = 2.4
    """Half the track length for one cart, m."""
    track_half_length_per_cart: float = 0.55
    """Half-length added per further cart, m."""
    velocity_range: float = 2.0
    """Cart speed at which the velocity sensors (S6/S7) saturate, m/s (paper: 2)."""
    angular_velocity_range: float = 5.0 * math.pi
    """Rod angular speed at which S8/S9 saturate, rad/s (paper: 5 pi)."""
    steps: int = 2000
    """Control steps of an episode (experiments: 2000; at most 3000)."""
    upright_angle: float = math.pi / 2
    """A rod counts as upright within this angle of the top, rad."""
    fitness_mode: str = "all"
    """Algorithm 1's fitness: ``all`` (steps with every rod upright, the paper's
    text) or ``mean`` (the mean over rods, its formula)."""
    reward: str = "height"
    """DDPG's reward per step: ``height``, ``slow-height``, ``height-product`` or ``upright``
    (module docstring); never the fitness."""
    termination_penalty: float = -5.0
    """Reward added on the step that ends an episode early (crash, tether, wall)."""
    initial_noise: float = 0.0
    """Half-width of the uniform noise on the start state (0: the nominal start)."""
    initial_angle: float = math.pi
    """Rod angle at the start, rad (pi: hanging down)."""

    def __post_init__(self) -> None:
        check_field_types(self)
        for name, allowed in _CHOICES.items():
            check_choice(name, getattr(self, name), allowed)
        check_range("n_carts", self.n_carts, 1, MAX_CARTS)
        check_range("substeps", self.substeps, 1, 1000)
        check_range("steps", self.steps, 1, STEP_CAP)
        for name in (
            "gravity",
            "cart_mass",
            "pole_mass",
            "pole_half_length",
            "dt",
            "motor_gain",
            "cart_width",
            "tether_length",
            "initial_spacing",
            "track_half_length_base",
            "velocity_range",
            "angular_velocity_range",
        ):
            check_range(name, getattr(self, name), 0.0, low_open=True)
        for name in ("cart_friction", "hinge_friction", "track_half_length_per_cart"):
            check_range(name, getattr(self, name), 0.0)
        check_range("motor_tau", self.motor_tau, 0.0, MAX_MOTOR_TAU, low_open=True)
        step = self.dt / self.substeps
        if self.motor == "velocity" and self.motor_tau < step:
            # The Euler-integrated lag overshoots when tau < h (and diverges beyond 2 h).
            raise ValueError(
                f"motor_tau must be in [dt / substeps = {step:g}, {MAX_MOTOR_TAU:g}] for the "
                f"velocity motor, got {self.motor_tau!r}"
            )
        if not 0 < self.upright_angle <= math.pi:
            raise ValueError(f"upright_angle must be in (0, pi], got {self.upright_angle!r}")
        if self.termination_penalty > 0:
            raise ValueError(f"termination_penalty must be <= 0, got {self.termination_penalty!r}")
        if not 0 <= self.initial_angle < 2 * math.pi:
            raise ValueError(f"initial_angle must be in [0, 2 pi), got {self.initial_angle!r}")
        if not 0 <= self.initial_noise <= 0.5:
            raise ValueError(f"initial_noise must be in [0, 0.5], got {self.initial_noise!r}")
        if self.tether_length <= self.cart_width:
            raise ValueError(
                f"tether_length must be > cart_width ({self.cart_width}), "
                f"got {self.tether_length!r}"
            )
        if not self.cart_width < self.initial_spacing < self.tether_length:
            raise ValueError(
                f"initial_spacing must be in ({self.cart_width}, {self.tether_length}) "
                f"(between cart_width and tether_length), got {self.initial_spacing!r}"
            )
        outer = (self.n_carts - 1) * self.initial_spacing / 2 + self.cart_width / 2
        if outer + self.initial_noise >= self.track_half_length:
            raise ValueError(
                f"the outer carts start off the track: (n_carts - 1) * initial_spacing / 2 "
                f"+ cart_width / 2 + initial_noise = {outer + self.initial_noise:.3f} m must be "
                f"< track_half_length_base + track_half_length_per_cart * (n_carts - 1) = "
                f"{self.track_half_length:.3f} m"
            )

    @classmethod
    def from_mapping(cls, values: dict) -> PendulumConfig:
        """Build from a plain mapping (YAML, CLI), refusing unknown keys by name."""
        check_keys("env", values, cls)
        return cls(**values)

    @property
    def track_half_length(self) -> float:
        """Half-length of the track [m]: ``base + per_cart * (n - 1)``."""
        return self.track_half_length_base + self.track_half_length_per_cart * (self.n_carts - 1)

    @property
    def observation_size(self) -> int:
        """Length of one environment's observation (10 sensors per cart)."""
        return SENSORS_PER_CART * self.n_carts

    def initial_positions(self) -> np.ndarray:
        """Cart centres at rest, evenly spaced about 0 [m], shape ``[n]``."""
        offsets = np.arange(self.n_carts) - (self.n_carts - 1) / 2
        return offsets * self.initial_spacing
