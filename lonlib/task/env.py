"""Gymnasium facade over :class:`lonlib.task.pendulum.CoupledPendulums` (one environment).

Registered as ``lonlib/CoupledPendulum-v1``; keyword arguments of ``gymnasium.make`` reach
:class:`~lonlib.config.pendulum.PendulumConfig` (``gymnasium.make("lonlib/CoupledPendulum-v1",
n_carts=1, reward="upright")``). Observation: normalised Table I sensors ``Box(0, 1, (10n,))``;
action: one value per cart ``Box(0, 1, (n,))``; reward: the config's reward; ``terminated`` on
collision / tether / boundary, ``truncated`` at ``config.steps``. ``info`` holds
``end_reason`` (an :class:`~lonlib.task.pendulum.EndReason` name), ``fitness`` (running
Algorithm 1 fitness) and ``upright`` (this step's fitness increment).

Observations are float32 by default (Gymnasium's convention, what RL libraries expect); with
``observation_dtype="float64"`` they are the simulator's sensors exactly, so that a stored
optimum (:func:`lonlib.storage.load_policy`) replays its stored fitness bit for bit: rounding
the sensors to float32 changes a chaotic episode (docs/rollout.md, "Replaying an optimum
outside lonlib").

Versions (Gymnasium bumps an id's version when its results change): ``v1`` has the calibrated
default physics (velocity motor, semi-implicit Euler); ``v0`` was registered before that
change. ``v0`` stays registered, makes the same environment as ``v1`` and warns
(``DeprecationWarning``); ask for the physics explicitly (``motor=``, ``integrator=``) to
rebuild an old one.
"""

from __future__ import annotations

import warnings
from typing import Any

import gymnasium as gym
import numpy as np

from lonlib.config import PendulumConfig
from lonlib.task.pendulum import CoupledPendulums, EndReason

ENV_ID = "lonlib/CoupledPendulum-v1"
OBSERVATION_DTYPES = ("float32", "float64")
DEPRECATED_ENV_ID = "lonlib/CoupledPendulum-v0"


class CoupledPendulumEnv(gym.Env):
    """The coupled inverted pendulums task as a ``gymnasium.Env`` (see module docstring)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 50}

    def __init__(
        self, render_mode: str | None = None, observation_dtype: str = "float32", **config: Any
    ) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if observation_dtype not in OBSERVATION_DTYPES:
            raise ValueError(
                f"observation_dtype must be one of {list(OBSERVATION_DTYPES)}, "
                f"got {observation_dtype!r}"
            )
        self.config = PendulumConfig(**config)
        self.render_mode = render_mode
        self.observation_dtype = np.dtype(observation_dtype)
        n = self.config.n_carts
        self.observation_space = gym.spaces.Box(
            0.0, 1.0, shape=(self.config.observation_size,), dtype=self.observation_dtype
        )
        self.action_space = gym.spaces.Box(0.0, 1.0, shape=(n,), dtype=np.float32)
        self.metadata = {**self.metadata, "render_fps": round(1.0 / self.config.dt)}
        self._sim = CoupledPendulums(self.config, 1)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode: rods hanging, carts at rest (plus the config's initial noise)."""
        super().reset(seed=seed)
        self._sim.rng = self.np_random
        self._sim.reset()
        return self._observation(), self._info(0.0)

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """One control step; see the module docstring for what comes back."""
        if self._sim.done[0]:
            raise RuntimeError("step() called on an ended episode: call reset() first")
        action = np.asarray(action, dtype=np.float64).reshape(1, self.config.n_carts)
        result = self._sim.step(action)
        return (
            self._observation(),
            float(result.reward[0]),
            bool(result.terminated[0]),
            bool(result.truncated[0]),
            self._info(float(result.upright[0])),
        )

    def render(self) -> np.ndarray | None:
        """An RGB frame of track, carts, tether and rods (``render_mode="rgb_array"``)."""
        if self.render_mode != "rgb_array":
            return None
        return render_frame(self.config, self._sim.x[0], self._sim.phi[0])

    def _observation(self) -> np.ndarray:
        return self._sim.observe()[0].astype(self.observation_dtype)

    def _info(self, upright: float) -> dict[str, Any]:
        return {
            "end_reason": EndReason(int(self._sim.end_reason[0])).name,
            "fitness": float(self._sim.fitness[0]),
            "upright": upright,
        }


def render_frame(
    config: PendulumConfig, x: np.ndarray, phi: np.ndarray, width: int = 600, height: int = 240
) -> np.ndarray:
    """Draw one state (cart centres ``x`` and angles ``phi``, shape ``[n]``) as ``[H, W, 3]``."""
    image = np.full((height, width, 3), 255, dtype=np.uint8)
    half = config.track_half_length
    scale = (width - 20) / (2 * half)
    ground = int(height * 0.7)

    def px(xm: float) -> float:
        return width / 2 + xm * scale

    _line(image, px(-half), ground, px(half), ground, (60, 60, 60), 2)
    for end in (-half, half):
        _line(image, px(end), ground - 25, px(end), ground + 10, (60, 60, 60), 3)
    cart_w, cart_h = config.cart_width * scale, 14
    for left, right in zip(x[:-1], x[1:], strict=True):
        _line(image, px(left), ground - 6, px(right), ground - 6, (150, 110, 40), 1)
    rod = 2 * config.pole_half_length * scale
    for xc, angle in zip(x, phi, strict=True):
        x0, y0 = px(xc), ground - cart_h
        image[int(y0) : ground, int(x0 - cart_w / 2) : int(x0 + cart_w / 2) + 1] = (40, 90, 170)
        tip = (x0 + rod * np.sin(angle), y0 - rod * np.cos(angle))
        _line(image, x0, y0, tip[0], tip[1], (200, 60, 40), 3)
    return image


def _line(
    image: np.ndarray, x0: float, y0: float, x1: float, y1: float, color, thickness: int
) -> None:
    """Rasterise a thick segment by sampling points along it (clipped to the image)."""
    count = int(max(abs(x1 - x0), abs(y1 - y0))) + 2
    xs = np.linspace(x0, x1, count)
    ys = np.linspace(y0, y1, count)
    r = thickness // 2
    for dx in range(-r, thickness - r):
        for dy in range(-r, thickness - r):
            cols = np.clip(np.round(xs + dx).astype(int), 0, image.shape[1] - 1)
            rows = np.clip(np.round(ys + dy).astype(int), 0, image.shape[0] - 1)
            image[rows, cols] = color


def make_deprecated_env(**kwargs: Any) -> CoupledPendulumEnv:
    """``lonlib/CoupledPendulum-v0``'s entry point: the ``v1`` environment, with a warning."""
    warnings.warn(
        f"{DEPRECATED_ENV_ID} is deprecated: it was registered before the default physics "
        f"changed (velocity motor, semi-implicit Euler) and now makes {ENV_ID}'s environment; "
        f"use {ENV_ID}",
        DeprecationWarning,
        stacklevel=2,
    )
    return CoupledPendulumEnv(**kwargs)


def register_envs() -> None:
    """Register ``lonlib/CoupledPendulum-v1`` and the deprecated ``v0`` with Gymnasium (once)."""
    if ENV_ID not in gym.registry:
        gym.register(id=ENV_ID, entry_point="lonlib.task.env:CoupledPendulumEnv")
    if DEPRECATED_ENV_ID not in gym.registry:
        gym.register(id=DEPRECATED_ENV_ID, entry_point="lonlib.task.env:make_deprecated_env")
