"""lonlib's flat Actor ``theta`` and Critic ``omega`` (paper Eq. 1,
:class:`lonlib.task.policy.NetSpec`) in and out of a Stable-Baselines3 policy.

Both sides are the same MLPs (three hidden layers of 20 sigmoids) with the same
``nn.Linear`` layout (weights ``[out, in]`` row-major, then biases); two things differ, and
the conversion keeps the functions, not the numbers:

* **Actor output.** SB3 squashes the actor's output with tanh onto [-1, 1] and maps that onto
  the action bounds; lonlib squashes with a sigmoid onto [0, 1] and maps that onto the same
  bounds (:meth:`lonlib.task.gymnasium_task.GymnasiumTask.env_action`). Since
  ``(tanh(x) + 1) / 2 = sigmoid(2x)``, lonlib's ``theta`` is SB3's actor with the output
  layer's weights and bias doubled (halved going into SB3; both exact in float32). The actor
  is TD3's and DDPG's ``actor.mu``, SAC's ``actor.latent_pi`` and its mean head
  ``actor.mu`` (SAC's ``log_std`` head is not in ``theta``).
* **Critic action input.** SB3's critics read the action in its [-1, 1] units ``a_s``,
  lonlib's in [0, 1] ``a`` (``a_s = 2a - 1``), so the first layer's action columns are doubled
  and their sum taken off the bias: ``W a_s + b = (2W) a + (b - W 1)``. ``omega`` is every
  critic of the policy (TD3 and SAC: both Q-networks; DDPG: one), one after the other, each in
  the task's critic layout; the bias shift is computed in float64 and rounded to float32, so a
  round trip through SB3 may move a bias by a float32 ulp.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from torch import nn

from lonlib.task.policy import NetSpec

Layers = list[tuple[np.ndarray, np.ndarray]]
"""One MLP as ``(weight [out, in], bias [out])`` per layer, input to output."""


def actor_linears(policy: Any) -> list[nn.Linear]:
    """The linear layers of the policy's deterministic actor, input to output."""
    actor = policy.actor
    modules = [*actor.latent_pi, actor.mu] if hasattr(actor, "latent_pi") else [*actor.mu]
    return [m for m in modules if isinstance(m, nn.Linear)]


def critic_linears(policy: Any) -> list[list[nn.Linear]]:
    """The linear layers of each of the policy's critics (Q-networks), input to output."""
    return [[m for m in q if isinstance(m, nn.Linear)] for q in policy.critic.q_networks]


def theta_of_layers(layers: Layers) -> np.ndarray:
    """lonlib's flat Actor (float32) of SB3's actor layers: the output layer doubled."""
    last = len(layers) - 1
    parts = []
    for i, (weight, bias) in enumerate(layers):
        factor = np.float32(2.0 if i == last else 1.0)
        parts += [weight.ravel() * factor, bias * factor]
    return np.concatenate(parts).astype(np.float32)


def layers_of_theta(spec: NetSpec, theta: np.ndarray) -> Layers:
    """SB3's actor layers (float32) of lonlib's flat Actor: the output layer halved."""
    layers = spec.unflatten(np.asarray(theta, dtype=np.float32))
    last = len(layers) - 1
    return [
        (w * np.float32(0.5), b * np.float32(0.5)) if i == last else (w.copy(), b.copy())
        for i, (w, b) in enumerate(layers)
    ]


def critic_of_layers(layers: Layers, action_size: int) -> np.ndarray:
    """lonlib's flat critic (float32) of one SB3 critic's layers: action columns doubled,
    their sum taken off the first bias."""
    (weight, bias), rest = layers[0], layers[1:]
    action_columns = weight[:, -action_size:].astype(np.float64)
    first_weight = weight.copy()
    first_weight[:, -action_size:] = weight[:, -action_size:] * np.float32(2.0)
    first_bias = (bias.astype(np.float64) - action_columns.sum(axis=1)).astype(np.float32)
    parts = [first_weight.ravel(), first_bias]
    for w, b in rest:
        parts += [w.ravel(), b]
    return np.concatenate(parts).astype(np.float32)


def layers_of_critic(spec: NetSpec, flat: np.ndarray, action_size: int) -> Layers:
    """One SB3 critic's layers (float32) of lonlib's flat critic: action columns halved,
    their (halved) sum added to the first bias."""
    layers = spec.unflatten(np.asarray(flat, dtype=np.float32))
    (weight, bias), rest = layers[0], layers[1:]
    first_weight = weight.copy()
    first_weight[:, -action_size:] = weight[:, -action_size:] * np.float32(0.5)
    shift = first_weight[:, -action_size:].astype(np.float64).sum(axis=1)
    first_bias = (bias.astype(np.float64) + shift).astype(np.float32)
    return [(first_weight, first_bias), *((w.copy(), b.copy()) for w, b in rest)]


def read_linears(linears: list[nn.Linear]) -> Layers:
    """The layers' parameters as float32 numpy copies."""
    return [
        (
            m.weight.detach().cpu().numpy().astype(np.float32),
            m.bias.detach().cpu().numpy().astype(np.float32),
        )
        for m in linears
    ]


def write_linears(linears: list[nn.Linear], layers: Layers) -> None:
    """Copy ``layers`` into the modules in place (the optimizers keep their parameters)."""
    if [tuple(m.weight.shape) for m in linears] != [w.shape for w, _ in layers]:
        raise ValueError(
            f"the SB3 network's layers {[tuple(m.weight.shape) for m in linears]} are not "
            f"lonlib's {[w.shape for w, _ in layers]}"
        )
    with torch.no_grad():
        for module, (weight, bias) in zip(linears, layers, strict=True):
            module.weight.copy_(torch.as_tensor(weight))
            module.bias.copy_(torch.as_tensor(bias))


def actor_theta(policy: Any) -> np.ndarray:
    """The policy's deterministic actor as lonlib's flat Actor."""
    return theta_of_layers(read_linears(actor_linears(policy)))


def critic_omega(policy: Any, action_size: int) -> np.ndarray:
    """Every critic of the policy as lonlib's flat Critic parameters, concatenated."""
    return np.concatenate(
        [critic_of_layers(read_linears(q), action_size) for q in critic_linears(policy)]
    ).astype(np.float32)


def load_parameters(
    policy: Any, theta: np.ndarray, omega: np.ndarray, actor: NetSpec, critic: NetSpec
) -> None:
    """Set the policy's actor to ``theta`` and its critics to ``omega`` (``critics`` times
    ``critic.n_params`` entries), then copy them into its target networks."""
    write_linears(actor_linears(policy), layers_of_theta(actor, theta))
    q_networks = critic_linears(policy)
    size, action_size = critic.n_params, actor.sizes[-1]
    if np.shape(omega) != (len(q_networks) * size,):
        raise ValueError(
            f"omega must hold {len(q_networks)} critic(s) of {size} parameters, got "
            f"{np.shape(omega)}"
        )
    for i, q in enumerate(q_networks):
        part = np.asarray(omega)[i * size : (i + 1) * size]
        write_linears(q, layers_of_critic(critic, part, action_size))
    if getattr(policy, "actor_target", None) is not None:
        policy.actor_target.load_state_dict(policy.actor.state_dict())
    policy.critic_target.load_state_dict(policy.critic.state_dict())


__all__ = [
    "actor_theta",
    "critic_omega",
    "critic_of_layers",
    "layers_of_critic",
    "layers_of_theta",
    "load_parameters",
    "theta_of_layers",
]
