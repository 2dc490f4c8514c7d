"""The Stable-Baselines3 model of a local search (:func:`make_model`): TD3, SAC or DDPG with
the paper's shapes and lonlib's hyperparameters ``h`` (:class:`lonlib.config.DDPGConfig`).

* Networks: actor and critics ``net_arch [20, 20, 20]``, ``nn.Sigmoid`` on every hidden layer
  (the paper's MLPs; SB3 adds tanh on the actor's output, which
  :mod:`lonlib.sb3.params` converts), on the CPU.
* ``learning_rate``, ``gamma``, ``tau``, ``batch_size``, ``buffer_size`` as they are;
  ``warmup_steps`` as ``learning_starts`` (uniform random actions before it); one gradient step
  per env step (``train_freq`` 1, ``gradient_steps`` 1).
* TD3 and DDPG explore with ``NormalActionNoise`` of standard deviation ``2 * noise_std``:
  SB3 adds it in its [-1, 1] action units, lonlib's ``noise_std`` is in the Actor's [0, 1].
  SAC explores with its own stochastic policy (no action noise); its entropy coefficient is
  SB3's default (``auto``, learnt from 1.0).
* TD3's and DDPG's other settings are SB3's (TD3: policy delay 2, target policy noise 0.2
  clipped at 0.5; DDPG: SB3's TD3 without them, one critic).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from torch import nn

from lonlib.config import DDPGConfig
from lonlib.task.policy import HIDDEN


def sb3_seed(seed: int) -> int:
    """The seed SB3 gets for a local search seeded ``seed`` (SB3 seeds numpy's legacy
    generator, which takes seeds below 2**32; ours are 64-bit)."""
    return int(np.random.SeedSequence([seed, 11]).generate_state(1, np.uint32)[0] >> 1)


def make_model(search: str, env: Any, hp: DDPGConfig, seed: int) -> Any:
    """The SB3 model of ``search`` (``sb3-td3``, ``sb3-sac``, ``sb3-ddpg``) on ``env`` (a
    :class:`lonlib.sb3.env.TrainingEnv`), seeded from ``seed``: its networks are SB3's random
    ones until :func:`lonlib.sb3.params.load_parameters` sets them."""
    from stable_baselines3 import DDPG, SAC, TD3
    from stable_baselines3.common.noise import NormalActionNoise
    from stable_baselines3.common.vec_env import DummyVecEnv

    algorithms = {"sb3-td3": TD3, "sb3-sac": SAC, "sb3-ddpg": DDPG}
    if search not in algorithms:
        raise ValueError(f"task.search {search!r} is not a Stable-Baselines3 search")
    actions = int(env.action_space.shape[0])
    options: dict[str, Any] = {}
    if search != "sb3-sac":
        options["action_noise"] = NormalActionNoise(
            np.zeros(actions), np.full(actions, 2.0 * hp.noise_std)
        )
    return algorithms[search](
        "MlpPolicy",
        DummyVecEnv([lambda: env]),
        learning_rate=hp.learning_rate,
        buffer_size=hp.buffer_size,
        learning_starts=hp.warmup_steps,
        batch_size=hp.batch_size,
        tau=hp.tau,
        gamma=hp.gamma,
        train_freq=1,
        gradient_steps=1,
        policy_kwargs={"net_arch": list(HIDDEN), "activation_fn": nn.Sigmoid},
        device="cpu",
        seed=sb3_seed(seed),
        verbose=0,
        **options,
    )


__all__ = ["make_model", "sb3_seed"]
