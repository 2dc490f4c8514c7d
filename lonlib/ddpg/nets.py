"""Actor and Critic networks with a leading agent dimension, trainable in torch.

:class:`BatchedMLP` holds ``k`` independent networks of one shape (``[k, out, in]`` weights)
so ``k`` agents train in one batched matrix product; ``k = 1`` is the single-agent case. The
flat parameter layout (paper Eq. 1) and the numpy forward of fixed parameters are
:mod:`lonlib.task.policy`'s (re-exported here). The autograd reference learner's
(:mod:`lonlib.ddpg.reference`): its parameters cross between host and device directly
(``torch.as_tensor``, ``.cpu()``), not through :mod:`lonlib.ddpg.devices`.
"""

from __future__ import annotations

import numpy as np
import torch

from lonlib.task.policy import HIDDEN, NetSpec, actor_spec, critic_spec, forward_numpy

__all__ = ["HIDDEN", "BatchedMLP", "NetSpec", "actor_spec", "critic_spec", "forward_numpy"]


class BatchedMLP(torch.nn.Module):
    """``k`` independent MLPs of one :class:`NetSpec`, evaluated with batched matmuls.

    ``forward(x)`` takes ``[k, B, in]`` and returns ``[k, B, out]``; agent ``i`` only ever
    sees its own weights, so gradients never mix between agents.
    """

    def __init__(self, spec: NetSpec, flat: torch.Tensor | np.ndarray) -> None:
        super().__init__()
        self.spec = spec
        flat = torch.as_tensor(np.asarray(flat, dtype=np.float32))
        if flat.ndim != 2:
            raise ValueError(f"flat parameters must be [k, {spec.n_params}], got {flat.shape}")
        self.weights = torch.nn.ParameterList()
        self.biases = torch.nn.ParameterList()
        for weight, bias in spec.unflatten(flat):
            self.weights.append(torch.nn.Parameter(weight.clone().contiguous()))
            self.biases.append(torch.nn.Parameter(bias.clone().contiguous()))
        # Plain lists: iterating a ParameterList costs more than a small layer's matmul.
        self.layers = list(zip(self.weights, self.biases, strict=True))
        self.tensors = [t for layer in self.layers for t in layer]

    @property
    def agents(self) -> int:
        """Number of independent networks ``k``."""
        return self.weights[0].shape[0]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``[k, B, in]`` -> ``[k, B, out]``."""
        last = len(self.layers) - 1
        for i, (weight, bias) in enumerate(self.layers):
            x = torch.baddbmm(bias.unsqueeze(1), x, weight.transpose(1, 2))
            if i < last or self.spec.sigmoid_output:
                x = torch.sigmoid(x)
        return x

    def flat(self) -> np.ndarray:
        """Current parameters as flat vectors ``[k, P]`` (float32, Eq. 1 order)."""
        with torch.no_grad():
            parts = []
            for weight, bias in zip(self.weights, self.biases, strict=True):
                parts += [weight.reshape(self.agents, -1), bias]
            return torch.cat(parts, dim=1).cpu().numpy()

    def load_flat(self, flat: np.ndarray | torch.Tensor) -> None:
        """Overwrite the parameters from flat vectors ``[k, P]``."""
        flat = torch.as_tensor(np.asarray(flat, dtype=np.float32))
        with torch.no_grad():
            for (weight, bias), (w_new, b_new) in zip(
                zip(self.weights, self.biases, strict=True), self.spec.unflatten(flat), strict=True
            ):
                weight.copy_(w_new)
                bias.copy_(b_new)
