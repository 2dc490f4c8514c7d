r"""Batched simulator of the coupled inverted pendulums task (Hamann et al. 2011; paper §II-A).

``n`` carts (1-5) move on a 1-D track. Each carries a uniform rod hinged at its centre; the
rods start hanging and must be swung up and balanced. Neighbouring carts are tethered: an
episode ends when two carts collide, when a tether is over-stretched, when a cart touches a
track end, or at the step limit. No public source gives the physics of the original
simulator, so everything physical below is **our documented default** unless marked
*paper*; every constant lives in :class:`PendulumConfig` and nowhere else.

Coordinates and units (SI)
--------------------------
* ``x``      cart centre [m], track centred on 0, positive to the right.
* ``x_dot``  cart velocity [m/s].
* ``phi``    rod angle [rad] measured from **upright**, positive when the tip leans to the
  right (+x), wrapped to ``[0, 2*pi)``: ``phi = 0`` upright, ``phi = pi`` hanging.
* ``phi_dot`` angular velocity [rad/s].

Motor models (``motor``): the default is the **velocity** motor (the command is the cart's
target speed, a speed servo with time constant ``motor_tau``), chosen by the calibration
study; ``"force"`` (the spec's first choice) and ``"acceleration"`` remain options.

With ``motor="force"`` the per-cart dynamics are the classic cart-pole (Barto et al. 1983,
with the rod equations as corrected by R. V. Florian, "Correct equations for the dynamics
of the cart-pole system", 2007),
uniform rod of mass ``m``, half-length ``l``, cart mass ``M``, hinge friction ``mu_p`` and
Barto's Coulomb cart friction ``mu_c sgn(x_dot)`` (not Florian's normal-force form)::

    phi_ddot = (g sin(phi) + cos(phi) * (-F - m l phi_dot^2 sin(phi) + mu_c sgn(x_dot)) / (M + m)
                - mu_p phi_dot / (m l))
               / (l (4/3 - m cos(phi)^2 / (M + m)))
    x_ddot   = (F + m l (phi_dot^2 sin(phi) - phi_ddot cos(phi)) - mu_c sgn(x_dot)) / (M + m)

With ``motor="acceleration"`` the motor sets the cart's acceleration directly and the rod
follows (same rod, same hinge friction)::

    x_ddot   = a_motor
    phi_ddot = 3 / (4 l) * (g sin(phi) - x_ddot cos(phi)) - 3 mu_p phi_dot / (4 m l^2)

With ``motor="velocity"`` the command is the cart's **target speed** ``v_cmd`` [m/s], which a
speed servo approaches with a first-order lag of time constant ``tau = motor_tau``; the rod
follows the resulting cart acceleration through the acceleration-mode rod equation (cart
mass and cart friction do not enter: the servo overrides them)::

    x_ddot   = (v_cmd - x_dot) / tau
    phi_ddot = 3 / (4 l) * (g sin(phi) - x_ddot cos(phi)) - 3 mu_p phi_dot / (4 m l^2)

The lag is integrated by the same Euler step ``h = dt / substeps`` as everything else, so
after ``k`` steps of a constant command ``x_dot = v_cmd + (x_dot_0 - v_cmd) (1 - h / tau)^k``
(the continuous response is ``exp(-t / tau)``; the two agree as ``h / tau -> 0``).
``tau >= h`` is required (the discrete lag then never overshoots); ``tau = h`` is an ideal
servo that reaches the commanded speed in one step.

Carts interact only through the termination rules (the tether is a chain, not a spring).
Integration: ``substeps`` Euler steps per control step of ``dt`` seconds. The default is
**semi-implicit (symplectic) Euler** (velocities first, then positions with the new
velocities), chosen by the calibration study (README, "Calibration study"): it keeps a
swinging rod's energy bounded, while ``integrator="euler"`` (explicit Euler, all derivatives
from the old state; the spec's first choice, kept as an option) feeds energy into it
(small-swing amplitude x sqrt(1 + w^2 dt^2) = x1.0032 per step, about x100-x400 over a
2000-step episode, like a hinge with slightly negative friction).
The energy and the horizontal momentum ``(M + m) x_dot + m l cos(phi) phi_dot`` of one
rod-and-cart (frictionless, no motor) are conserved by the continuous equations and are used
by the tests::

    E = 1/2 (M + m) x_dot^2 + m l cos(phi) x_dot phi_dot + 2/3 m l^2 phi_dot^2 + m g l cos(phi)

Motor (paper Table I and §III-C)
--------------------------------
The Actor outputs ``a`` in [0, 1] per cart; the *single action conversion* (paper) gives
the two actuators ``(A0, A1) = (254 (0.5 - a), 0)`` if ``a < 0.5`` else ``(0, 254 (a - 0.5))``
and the motor command ``u = 2 (A0/127 - A1/127)`` in [-2, 2] (paper), i.e. ``u = 2 - 4a``.
``u > 0`` drives the cart to the left (paper: "acceleration to left when A1 - A2 > 0"), so
the horizontal force is ``F = -motor_gain * u`` newtons (ours: gain 1 N per unit), or the
acceleration ``-motor_gain * u`` m/s^2 in acceleration mode, or the target speed
``v_cmd = -motor_gain * u`` m/s in velocity mode (gain 1: the command range is the +-2 m/s
of the velocity sensors S6/S7, the paper's inputs that "dictate the speed"). ``a = 1`` is
full push right, ``a = 0`` full push left, ``a = 0.5`` no push (velocity mode: stand still).

Sensors (paper Table I), per cart, in [0, 127]; networks see them divided by 127
----------------------------------------------------------------------------------
=====  =====================================================================
S0     phi in [0, pi/2)      -> 127..0, else 0
S1     phi in [3pi/2, 2pi)   -> 0..127, else 0
S2     phi in [pi/2, pi)     -> 127..0, else 0
S3     phi in [pi, 3pi/2)    -> 0..127, else 0
S4/S5  proximity left/right: neighbour centre distance ``cart_width..tether_length`` ->
       127..0 (clipped). An end cart's outer side senses the track end as a virtual
       neighbour whose edge is the track end (ours: distance = centre-to-end + width/2, so
       touching the end reads 127 exactly like touching a cart).
S6/S7  cart velocity in [-2, 0] -> 127..0 / [0, 2] -> 0..127, saturating
S8/S9  angular velocity in [-5pi, 0] -> 127..0 / [0, 5pi] -> 0..127, saturating
=====  =====================================================================
With several carts the observation is all carts' sensors concatenated, cart by cart
(``[B, 10 n]``).

Termination (paper; thresholds ours)
------------------------------------
collision: neighbour centre distance < ``cart_width``; tether: > ``tether_length``;
boundary: a cart edge beyond ``track_half_length`` = 2.4 + 0.55 (n - 1) m. When several rules
fire on one step the reason reported is the first of collision, tether, boundary. The step
limit (``steps``, hard cap 3000, paper) truncates.

Fitness (paper Algorithm 1)
---------------------------
A rod is upright when ``|wrap(phi)| < upright_angle`` (wrap into (-pi, pi]). After every
executed step (the terminating one included) the step's upright value is added: 1 if *all*
rods are upright (``fitness_mode="all"``, the paper's text) or the fraction of upright rods
(``"mean"``, Algorithm 1's double sum). Fitness = sum / ``steps``: an early end is
penalised, never rescaled.

DDPG reward per step (ours; the LON's fitness is always Algorithm 1's)
---------------------------------------------------------------------
``height``: mean over rods of ``(1 + cos(phi)) / 2`` (1 upright, 0 hanging) plus
``termination_penalty`` on a step that ends the episode by collision, tether or boundary.
``slow-height``: the same with each rod's height scaled by
``1 - min(|phi_dot| / angular_velocity_range, 1)``, so a slow upright rod earns more than a
spinning one. ``height-product``: the **product** over rods of ``(1 + cos(phi)) / 2`` plus
the same penalty, aligned with the "all rods upright" fitness: one rod balanced and one
spinning earns ~0.5 per step on average, not the ~0.75 of ``height`` (a comfortable local
optimum), against 1 for both up; with one rod it equals ``height``.
``upright``: the step's fitness increment divided by ``steps`` (sparse).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from lonlib.config import PendulumConfig
from lonlib.config.pendulum import SENSORS_PER_CART
from lonlib.task import compiled
from lonlib.util import portable_math

FloatArray = np.ndarray
Policy = Callable[[np.ndarray], np.ndarray]
"""A deterministic policy: normalised sensors ``[B, 10 n]`` -> actions ``[B, n]`` in [0, 1]."""


class EndReason(IntEnum):
    """Why an episode ended (``RUNNING`` while it has not)."""

    RUNNING = 0
    STEP_LIMIT = 1
    COLLISION = 2
    TETHER = 3
    BOUNDARY = 4


def motor_command(actions: FloatArray) -> FloatArray:
    """Motor command ``u = 2 (A0/127 - A1/127)`` in [-2, 2] (paper Table I); ``u > 0`` = left.

    With the single action conversion (A0, A1) = (254 (0.5 - a), 0) for a < 0.5, else
    (0, 254 (a - 0.5)), both branches reduce to ``u = 2 - 4a``.
    """
    return 2.0 - 4.0 * np.clip(actions, 0.0, 1.0)


def wrap_angle(phi: FloatArray) -> FloatArray:
    """Wrap angles into ``(-pi, pi]`` (0 = upright)."""
    wrapped = np.mod(phi + np.pi, 2 * np.pi) - np.pi
    return np.where(wrapped == -np.pi, np.pi, wrapped)


def total_energy(
    config: PendulumConfig, x_dot: FloatArray, phi: FloatArray, phi_dot: FloatArray
) -> FloatArray:
    """Mechanical energy of each cart-and-rod [J] (see the module docstring)."""
    m, big_m, l = config.pole_mass, config.cart_mass, config.pole_half_length
    return (
        0.5 * (big_m + m) * x_dot**2
        + m * l * portable_math.cos(phi) * x_dot * phi_dot
        + (2.0 / 3.0) * m * l**2 * phi_dot**2
        + m * config.gravity * l * portable_math.cos(phi)
    )


def sensors(
    config: PendulumConfig, x: FloatArray, x_dot: FloatArray, phi: FloatArray, phi_dot: FloatArray
) -> FloatArray:
    """Table I sensors normalised to [0, 1], shape ``[B, 10 n]`` (cart by cart).

    Arguments are ``[B, n]`` arrays; ``phi`` must already lie in ``[0, 2 pi)``.
    """
    q = phi / (0.5 * np.pi)  # quadrant coordinate in [0, 4)
    s0 = np.where(q < 1.0, 1.0 - q, 0.0)
    s1 = np.where(q >= 3.0, q - 3.0, 0.0)
    s2 = np.where((q >= 1.0) & (q < 2.0), 2.0 - q, 0.0)
    s3 = np.where((q >= 2.0) & (q < 3.0), q - 2.0, 0.0)

    half, width = config.track_half_length, config.cart_width
    batch = x.shape[0]
    walls = np.full((batch, 1), half + 0.5 * width)
    padded = np.concatenate([-walls, x, walls], axis=1)
    gaps = np.diff(padded, axis=1)  # [B, n + 1] centre distances, walls as virtual carts
    proximity = np.clip((config.tether_length - gaps) / (config.tether_length - width), 0.0, 1.0)

    v = np.clip(x_dot / config.velocity_range, -1.0, 1.0)
    w = np.clip(phi_dot / config.angular_velocity_range, -1.0, 1.0)
    per_cart = np.stack(
        [
            s0,
            s1,
            s2,
            s3,
            proximity[:, :-1],
            proximity[:, 1:],
            np.maximum(-v, 0.0),
            np.maximum(v, 0.0),
            np.maximum(-w, 0.0),
            np.maximum(w, 0.0),
        ],
        axis=2,
    )  # [B, n, 10]
    return per_cart.reshape(batch, -1)


@dataclass
class StepResult:
    """What one batched step produced, one entry per environment (``[B]`` arrays)."""

    reward: FloatArray
    upright: FloatArray  # this step's fitness increment before dividing by ``steps``
    upright_each: np.ndarray  # [B, n] bool: each rod upright after this step (False if ended)
    terminated: np.ndarray  # ended by collision, tether or boundary on this step
    truncated: np.ndarray  # reached the step limit on this step
    end_reason: np.ndarray  # EndReason per environment (RUNNING if still going)


class CoupledPendulums:
    """``B`` independent coupled-pendulum environments stepped together (arrays ``[B, n]``).

    Environments that have ended stay frozen (state, step count and fitness unchanged)
    until :meth:`reset` re-initialises them. There is no loop over carts or environments.
    """

    # The per-environment state (``[B, n]`` or ``[B]`` arrays); the rest is configuration,
    # its derived constants and the generator ``rng``.
    STATE_ARRAYS = (
        "x",
        "x_dot",
        "phi",
        "phi_dot",
        "step_count",
        "upright_sum",
        "upright_all_sum",
        "upright_mean_sum",
        "end_reason",
    )

    def __init__(
        self,
        config: PendulumConfig,
        batch_size: int = 1,
        seed: int | np.random.Generator | None = None,
    ) -> None:
        if not isinstance(batch_size, (int, np.integer)) or batch_size < 1:
            raise ValueError(f"batch_size must be an integer >= 1, got {batch_size!r}")
        self.config = config
        self.batch_size = int(batch_size)
        shape = (self.batch_size, config.n_carts)
        self.x = np.zeros(shape)
        self.x_dot = np.zeros(shape)
        self.phi = np.full(shape, config.initial_angle)
        self.phi_dot = np.zeros(shape)
        self.step_count = np.zeros(self.batch_size, dtype=np.int64)
        self.upright_sum = np.zeros(self.batch_size)  # by the config's fitness_mode
        self.upright_all_sum = np.zeros(self.batch_size)  # steps with every rod upright
        self.upright_mean_sum = np.zeros(self.batch_size)  # sum of the upright share
        self.end_reason = np.zeros(self.batch_size, dtype=np.int8)
        self._cos_upright = float(portable_math.cos(np.float64(config.upright_angle)))
        self.rng = np.random.default_rng(seed)
        self.reset()

    # ------------------------------------------------------------------ state
    @property
    def done(self) -> np.ndarray:
        """``[B]`` bool: the environment has ended (any reason)."""
        return self.end_reason != EndReason.RUNNING

    @property
    def fitness(self) -> FloatArray:
        """``[B]`` running fitness (Algorithm 1) under the config's ``fitness_mode``:
        upright sum / nominal steps."""
        return self.upright_sum / self.config.steps

    @property
    def fitness_all(self) -> FloatArray:
        """``[B]`` running fitness with "all rods upright" per step (the paper's text)."""
        return self.upright_all_sum / self.config.steps

    @property
    def fitness_mean(self) -> FloatArray:
        """``[B]`` running fitness with the share of upright rods per step (Algorithm 1's
        double sum over steps and carts, divided by the carts)."""
        return self.upright_mean_sum / self.config.steps

    def reset(self, mask: np.ndarray | None = None, noise: np.ndarray | None = None) -> None:
        """Put environments (all, or those where ``mask`` is true) in the initial state.

        Carts at rest evenly spaced about 0, rods at ``initial_angle`` (default hanging).
        With ``initial_noise`` > 0 each of x, x_dot, phi, phi_dot gets uniform noise in
        ``[-noise, noise]`` drawn from the simulator's generator (``seed`` at construction),
        so a seed fixes the trajectory.
        ``noise`` (``[4, k, n]`` for the ``k`` environments reset, already scaled) overrides
        that draw, for callers that give every environment its own random stream.
        """
        cfg = self.config
        index = np.arange(self.batch_size) if mask is None else np.flatnonzero(mask)
        k, n = index.size, cfg.n_carts
        x0 = np.broadcast_to(cfg.initial_positions(), (k, n))
        state = [x0, np.zeros((k, n)), np.full((k, n), cfg.initial_angle), np.zeros((k, n))]
        if noise is None and cfg.initial_noise > 0:
            noise = self.rng.uniform(-cfg.initial_noise, cfg.initial_noise, size=(4, k, n))
        if noise is not None:
            state = [s + e for s, e in zip(state, noise, strict=True)]
        self.x[index], self.x_dot[index], self.phi[index], self.phi_dot[index] = state
        self.phi[index] = np.mod(self.phi[index], 2 * np.pi)
        self.step_count[index] = 0
        self.upright_sum[index] = 0.0
        self.upright_all_sum[index] = 0.0
        self.upright_mean_sum[index] = 0.0
        self.end_reason[index] = EndReason.RUNNING

    def select(self, index: np.ndarray | list[int]) -> CoupledPendulums:
        """A simulator of the environments at ``index`` (repeats allowed), in that order,
        with their current states; its generator continues this one's stream."""
        index = np.asarray(index, dtype=np.int64)
        out = CoupledPendulums.__new__(CoupledPendulums)
        out.__dict__.update(self.__dict__)
        out.batch_size = int(index.size)
        for name in self.STATE_ARRAYS:
            setattr(out, name, getattr(self, name)[index].copy())
        return out

    def observe(self) -> FloatArray:
        """Normalised Table I sensors of every environment, ``[B, 10 n]`` (compiled when
        :mod:`lonlib.task.compiled` can, else :func:`sensors`; the same bits)."""
        module = compiled.kernels()
        if module is None:
            return sensors(self.config, self.x, self.x_dot, self.phi, self.phi_dot)
        out = np.empty((self.batch_size, SENSORS_PER_CART * self.config.n_carts))
        fc, ic = compiled.pack(self.config)
        module.observe_batch(fc, ic, *self._state_arrays(), out)
        return out

    def _state_arrays(self) -> tuple[np.ndarray, ...]:
        """x, x_dot, phi, phi_dot as C-contiguous float64 arrays (what the kernels take)."""
        return tuple(
            np.ascontiguousarray(a, dtype=np.float64)
            for a in (self.x, self.x_dot, self.phi, self.phi_dot)
        )

    # ------------------------------------------------------------------ dynamics
    def _accelerations(
        self, x_dot: FloatArray, phi: FloatArray, phi_dot: FloatArray, drive: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """``x_ddot, phi_ddot`` for the motor output ``drive`` (force [N], acceleration
        [m/s^2] or target speed [m/s], by motor model)."""
        cfg = self.config
        m, l, g = cfg.pole_mass, cfg.pole_half_length, cfg.gravity
        sin, cos = portable_math.sin_cos(phi)
        if cfg.motor == "force":
            total = cfg.cart_mass + m
            friction = cfg.cart_friction * np.sign(x_dot)
            temp = (-drive - m * l * phi_dot**2 * sin + friction) / total
            phi_ddot = (g * sin + cos * temp - cfg.hinge_friction * phi_dot / (m * l)) / (
                l * (4.0 / 3.0 - m * cos**2 / total)
            )
            x_ddot = (drive + m * l * (phi_dot**2 * sin - phi_ddot * cos) - friction) / total
        else:
            x_ddot = drive if cfg.motor == "acceleration" else (drive - x_dot) / cfg.motor_tau
            phi_ddot = 0.75 / l * (g * sin - x_ddot * cos) - 0.75 * cfg.hinge_friction * (
                phi_dot / (m * l * l)
            )
        return x_ddot, phi_ddot

    def step(self, actions: FloatArray) -> StepResult:
        """Advance every running environment by one control step of ``dt`` seconds.

        ``actions``: ``[B, n]`` actor outputs in [0, 1] (clipped). Returns rewards, fitness
        increments and end flags; ended environments do not move and earn nothing. Compiled
        when :mod:`lonlib.task.compiled` can, else the numpy definition below; the same bits.
        """
        actions = np.asarray(actions, dtype=np.float64)
        if actions.shape != self.x.shape:
            raise ValueError(f"actions must have shape {self.x.shape}, got {actions.shape}")
        module = compiled.kernels()
        if module is None:
            return self._step_numpy(actions)
        batch, n = self.x.shape
        x, x_dot, phi, phi_dot = (a.copy() for a in self._state_arrays())
        step_count = self.step_count.astype(np.int64, copy=True)
        sums = np.stack([self.upright_sum, self.upright_all_sum, self.upright_mean_sum], axis=1)
        end_reason = self.end_reason.astype(np.int8, copy=True)
        reward, upright = np.empty(batch), np.empty(batch)
        upright_each = np.empty((batch, n), dtype=bool)
        terminated, truncated = np.empty(batch, dtype=bool), np.empty(batch, dtype=bool)
        reported = np.empty(batch, dtype=np.int8)
        fc, ic = compiled.pack(self.config)
        module.step_batch(
            fc, ic, x, x_dot, phi, phi_dot, step_count, sums, end_reason,
            np.ascontiguousarray(actions), reward, upright, upright_each, terminated,
            truncated, reported,
        )  # fmt: skip
        self.x, self.x_dot, self.phi, self.phi_dot = x, x_dot, phi, phi_dot
        self.step_count, self.end_reason = step_count, end_reason
        self.upright_sum, self.upright_all_sum, self.upright_mean_sum = (
            np.ascontiguousarray(sums[:, i]) for i in range(3)
        )
        return StepResult(reward, upright, upright_each, terminated, truncated, reported)

    def _step_numpy(self, actions: FloatArray) -> StepResult:
        """:meth:`step`'s numpy definition (the oracle of the compiled kernel)."""
        cfg = self.config
        running = ~self.done
        drive = -cfg.motor_gain * motor_command(actions)
        h = cfg.dt / cfg.substeps
        x, x_dot, phi, phi_dot = self.x, self.x_dot, self.phi, self.phi_dot
        for _ in range(cfg.substeps):
            x_ddot, phi_ddot = self._accelerations(x_dot, phi, phi_dot, drive)
            if cfg.integrator == "euler":
                x, phi = x + h * x_dot, phi + h * phi_dot
                x_dot, phi_dot = x_dot + h * x_ddot, phi_dot + h * phi_ddot
            else:
                x_dot, phi_dot = x_dot + h * x_ddot, phi_dot + h * phi_ddot
                x, phi = x + h * x_dot, phi + h * phi_dot
        phi = np.mod(phi, 2 * np.pi)

        keep = running[:, None]
        self.x = np.where(keep, x, self.x)
        self.x_dot = np.where(keep, x_dot, self.x_dot)
        self.phi = np.where(keep, phi, self.phi)
        self.phi_dot = np.where(keep, phi_dot, self.phi_dot)
        self.step_count += running

        cos = portable_math.cos(self.phi)
        upright_each = (cos > self._cos_upright) & running[:, None]
        upright_all = upright_each.all(axis=1).astype(np.float64)
        upright_mean = upright_each.mean(axis=1)
        self.upright_all_sum += upright_all
        self.upright_mean_sum += upright_mean
        upright = upright_all if cfg.fitness_mode == "all" else upright_mean
        self.upright_sum += upright

        reason = self._termination_reason()
        terminated = running & (reason != EndReason.RUNNING)
        truncated = running & ~terminated & (self.step_count >= cfg.steps)
        reason = np.where(truncated, EndReason.STEP_LIMIT, reason)
        self.end_reason = np.where(running, reason, self.end_reason).astype(np.int8)

        if cfg.reward == "upright":
            reward = upright / cfg.steps
        else:
            height = 0.5 * (1.0 + cos)
            if cfg.reward == "slow-height":
                speed = np.abs(self.phi_dot) / cfg.angular_velocity_range
                height = height * (1.0 - np.minimum(speed, 1.0))
            shaped = height.prod(axis=1) if cfg.reward == "height-product" else height.mean(axis=1)
            reward = shaped + cfg.termination_penalty * terminated
        reward = reward * running
        return StepResult(
            reward=reward,
            upright=upright,
            upright_each=upright_each,
            terminated=terminated,
            truncated=truncated,
            end_reason=np.where(running, self.end_reason, EndReason.RUNNING).astype(np.int8),
        )

    def _termination_reason(self) -> np.ndarray:
        """``[B]`` EndReason from the current positions (collision > tether > boundary)."""
        cfg = self.config
        boundary = (np.abs(self.x) + 0.5 * cfg.cart_width > cfg.track_half_length).any(axis=1)
        reason = np.where(boundary, EndReason.BOUNDARY, EndReason.RUNNING)
        if cfg.n_carts > 1:
            gaps = np.diff(self.x, axis=1)
            reason = np.where((gaps > cfg.tether_length).any(axis=1), EndReason.TETHER, reason)
            reason = np.where((gaps < cfg.cart_width).any(axis=1), EndReason.COLLISION, reason)
        return reason
