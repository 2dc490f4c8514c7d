"""Actor and Critic as flat parameter vectors (paper Eq. 1), and the Actor's numpy forward.

Both are plain MLPs with a sigmoid on every layer except the Critic's output (paper
§III-B): Actor ``[10n, 20, 20, 20, n]``, Critic ``[11n, 20, 20, 20, 1]`` (2623 parameters
together for two carts). A network's parameters are one flat float vector in the paper's
order (Eq. 1): layer by layer, the weights (row-major ``[out, in]``, i.e. neuron by neuron)
then the biases.

:func:`forward_numpy` evaluates fixed parameters in numpy with defined arithmetic (the one
greedy rollout's, :mod:`lonlib.task.rollout`); no torch here. The trainable torch networks
are :class:`lonlib.ddpg.nets.BatchedMLP`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from lonlib.util.portable_math import sigmoid

HIDDEN = (20, 20, 20)


@dataclass(frozen=True)
class NetSpec:
    """Shape of one MLP: layer sizes including input and output, and the output squashing."""

    sizes: tuple[int, ...]
    sigmoid_output: bool

    @cached_property
    def layers(self) -> tuple[tuple[int, int], ...]:
        """``(in, out)`` of every layer."""
        return tuple(zip(self.sizes[:-1], self.sizes[1:], strict=True))

    @cached_property
    def offsets(self) -> tuple[tuple[int, int, int], ...]:
        """``(weight start, bias start, bias end)`` of every layer in the flat vector."""
        out, start = [], 0
        for fan_in, fan_out in self.layers:
            bias = start + fan_in * fan_out
            out.append((start, bias, bias + fan_out))
            start = bias + fan_out
        return tuple(out)

    @property
    def n_params(self) -> int:
        """Number of trainable parameters (length of the flat vector)."""
        return self.offsets[-1][2]

    def unflatten(self, flat: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """Views ``(W [..., out, in], b [..., out])`` per layer of flat vectors ``[..., P]``."""
        if flat.shape[-1] != self.n_params:
            raise ValueError(f"flat parameters must have {self.n_params} entries, got {flat.shape}")
        lead = flat.shape[:-1]
        return [
            (flat[..., w:b].reshape(*lead, fan_out, fan_in), flat[..., b:e])
            for (fan_in, fan_out), (w, b, e) in zip(self.layers, self.offsets, strict=True)
        ]

    def initial(self, rng: np.random.Generator) -> np.ndarray:
        """A fresh flat vector, PyTorch ``nn.Linear``'s default: U(-1/sqrt(in), 1/sqrt(in))."""
        parts = []
        for fan_in, fan_out in self.layers:
            bound = 1.0 / math.sqrt(fan_in)
            parts.append(rng.uniform(-bound, bound, size=fan_in * fan_out))
            parts.append(rng.uniform(-bound, bound, size=fan_out))
        return np.concatenate(parts).astype(np.float32)


def actor_spec(n_carts: int) -> NetSpec:
    """Actor: all carts' sensors in, one action in [0, 1] per cart out."""
    return NetSpec((10 * n_carts, *HIDDEN, n_carts), sigmoid_output=True)


def critic_spec(n_carts: int) -> NetSpec:
    """Critic: sensors and actions in, one unbounded Q-value out."""
    return NetSpec((11 * n_carts, *HIDDEN, 1), sigmoid_output=False)


def forward_numpy(spec: NetSpec, flat: np.ndarray, inputs: np.ndarray) -> np.ndarray:
    """Evaluate fixed parameters in numpy with defined arithmetic (the greedy rollout's).

    ``flat`` is one vector ``[P]`` (shared by every row of ``inputs [B, in]``) or one vector
    per row ``[B, P]`` (row ``b`` evaluated by network ``b``, for batched evaluation of many
    policies). Returns ``[B, out]`` in float64.

    The arithmetic is defined, so that a row's output is the same bits whatever the batch,
    the row's position, numpy's CPU dispatch or the CPU: parameters and inputs are cast to
    float64 (exact); each neuron sums ``w[o, i] * h[i]`` strictly from ``i = 0`` upwards
    (an ``add.accumulate``, sequential by definition, never a BLAS or SIMD reduction), then
    adds its bias; the activation is :func:`lonlib.util.portable_math.sigmoid`.
    """
    flat = np.asarray(flat, dtype=np.float64)
    h = np.asarray(inputs, dtype=np.float64)
    if h.ndim != 2:
        raise ValueError(f"inputs must have shape [B, {spec.sizes[0]}], got {h.shape}")
    layers = spec.unflatten(flat)
    for i, (weight, bias) in enumerate(layers):
        products = h[:, None, :] * weight  # [B, out, in]; weight [out, in] or [B, out, in]
        h = np.add.accumulate(products, axis=2)[:, :, -1] + bias
        if i < len(layers) - 1 or spec.sigmoid_output:
            h = sigmoid(h)
    return h
