"""A lean DDPG learner: ``k`` agents' Actor, Critic, targets and Adam state in flat buffers,
updated with hand-written forward and backward passes.

The algorithm is exactly :func:`lonlib.ddpg.reference.autograd_update` (tested to float
tolerance against it): critic MSE towards ``r + gamma * not_done * Q'(s', mu'(s'))``, actor
loss ``-Q(s, mu(s))`` through the freshly updated critic without touching the critic's
weights, Adam (``torch.optim.Adam``'s math, bias correction included), soft targets
``target <- (1 - tau) target + tau net``, per-agent losses summed so agent ``i``'s gradient
is its own. What makes it lean (one update is 82 tensor operations, no autograd graph):

* **one flat buffer per network kind**: ``[2, k, P]`` holding the online and target
  parameters, so one batched matmul per layer evaluates both (the actor on ``s`` and the
  target actor on ``s'``; the critic on ``(s, a)`` and the target critic on ``(s', mu'(s'))``),
  one ``lerp_`` is the soft update and Adam runs over ``[k, P]`` with a handful of ops;
* **the bias is a weight column** (internal layout: per layer ``[out, in + 1]``, row-major)
  and every hidden activation carries a row of ones, so a layer is one ``bmm`` and its
  weight and bias gradients come out of one ``bmm``;
* **activations are kept feature-major** ``[k, features, B]`` and reused by the backward
  pass (the sigmoid's derivative is ``s (1 - s)``), every buffer is preallocated and every
  step writes in place;
* **per-agent Adam step counts**, so one agent's slot can be reset and reused; they and the
  bias-corrected Adam coefficients (gathered from a table by step) live on the device, so an
  update copies nothing between host and device.

Parameters enter and leave in the paper's flat order (Eq. 1, :class:`lonlib.task.policy.NetSpec`);
the internal layout differs only by a permutation (bias columns; the critic's first layer
reads ``(a, s)`` instead of ``(s, a)`` so the actor's input ``s`` sits in the same buffer).
Everything is a device-agnostic torch tensor: the same code runs on CPU and CUDA, with no
branch by device; parameters cross between host and device only through
:mod:`lonlib.ddpg.devices` (in :meth:`LeanDDPG.actor_flat` and the like).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from lonlib.ddpg.devices import to_device, to_host
from lonlib.ddpg.streams import SIMD_PAD
from lonlib.task.policy import NetSpec

BETAS = (0.9, 0.999)  # torch.optim.Adam's defaults, as the autograd reference uses
EPS = 1e-8
# Beyond this many steps both float32 bias-correction coefficients are exactly 1 and -lr.
ADAM_TABLE_STEPS = 20_000


@dataclass(frozen=True)
class _Layout:
    """Where each layer's ``[out, in + 1]`` block sits in a network's internal flat vector,
    and the permutation between the internal order and Eq. 1."""

    spec: NetSpec
    blocks: tuple[tuple[int, int, int], ...]  # (start, out, in + 1) per layer
    to_paper: np.ndarray  # internal index of every Eq. 1 entry: paper = internal[to_paper]
    to_internal: np.ndarray  # paper index of every internal entry: internal = paper[...]

    @classmethod
    def of(cls, spec: NetSpec, first_columns: np.ndarray | None = None) -> _Layout:
        """``first_columns[i]``: internal column of the first layer's input ``i`` (identity
        by default); the bias is always the last column."""
        blocks, to_paper, start = [], [], 0
        for index, (fan_in, fan_out) in enumerate(spec.layers):
            columns = np.arange(fan_in)
            if index == 0 and first_columns is not None:
                columns = np.asarray(first_columns)
            rows = np.arange(fan_out)[:, None] * (fan_in + 1)
            to_paper.append(start + (rows + columns[None, :]).ravel())  # weights, row-major
            to_paper.append(start + rows[:, 0] + fan_in)  # biases
            blocks.append((start, fan_out, fan_in + 1))
            start += fan_out * (fan_in + 1)
        paper = np.concatenate(to_paper)
        return cls(spec, tuple(blocks), paper, np.argsort(paper))

    def views(self, flat: torch.Tensor) -> list[torch.Tensor]:
        """Per-layer ``[m, out, in + 1]`` views of flat vectors ``[m, P]``."""
        m = flat.shape[0]
        return [flat[:, s : s + o * i].view(m, o, i) for s, o, i in self.blocks]


class LeanDDPG:
    """``k`` DDPG agents (Actor, Critic, their targets, Adam) in flat buffers.

    ``update(batch)`` runs one DDPG update of every agent (see the module docstring);
    ``act(obs)`` is the greedy Actor; ``actor_flat()``/``critic_flat()`` export the online
    parameters and ``reset_agent(i, theta, omega)`` restarts one agent's slot (parameters,
    targets, Adam moments and step count) for reuse.
    """

    per_agent_state = True  # each agent's state is reset, selected and loaded on its own

    def __init__(
        self,
        actor: NetSpec,
        critic: NetSpec,
        thetas: np.ndarray,
        omegas: np.ndarray,
        *,
        learning_rate: float,
        gamma: float,
        tau: float,
        device: str | torch.device = "cpu",
    ) -> None:
        obs_size, act_size = actor.sizes[0], actor.sizes[-1]
        if not actor.sigmoid_output or critic.sigmoid_output:
            raise ValueError("the actor's output must be squashed and the critic's must not")
        if critic.sizes[0] != obs_size + act_size or critic.sizes[-1] != 1:
            raise ValueError(
                f"critic sizes {critic.sizes} do not fit actor sizes {actor.sizes}: "
                f"the critic reads {obs_size + act_size} inputs and returns 1 value"
            )
        self.device = torch.device(device)
        self.obs_size, self.act_size = obs_size, act_size
        self.learning_rate, self.gamma, self.tau = learning_rate, gamma, tau
        # The critic's first layer reads (a, s): internal columns act_size.. hold s.
        critic_columns = np.r_[np.arange(obs_size) + act_size, np.arange(act_size)]
        self.actor_layout = _Layout.of(actor)
        self.critic_layout = _Layout.of(critic, critic_columns)

        thetas = self._internal(self.actor_layout, thetas)
        omegas = self._internal(self.critic_layout, omegas)
        k = self.agents = thetas.shape[0]
        if omegas.shape[0] != k:
            raise ValueError(f"{k} actors but {omegas.shape[0]} critics")
        # Actor: [target, online]; critic: [online, target] (matches the input slots below).
        self.actor_params = torch.stack([thetas, thetas])
        self.critic_params = torch.stack([omegas, omegas])
        self.actor_grad = torch.zeros_like(thetas)
        self.critic_grad = torch.zeros_like(omegas)
        self.actor_moments = torch.zeros(2, *thetas.shape, device=self.device)
        self.critic_moments = torch.zeros(2, *omegas.shape, device=self.device)
        self.adam_steps = torch.zeros(k, dtype=torch.int64, device=self.device)  # per agent
        # Adam coefficients [sqrt(bias correction 2), -lr / bias correction 1] by step (index
        # 0 unused), computed in float64 like torch.optim.Adam, gathered per agent each update.
        steps = np.arange(ADAM_TABLE_STEPS + 1, dtype=np.float64)
        with np.errstate(divide="ignore"):
            table = np.stack(
                [np.sqrt(1.0 - BETAS[1] ** steps), -learning_rate / (1.0 - BETAS[0] ** steps)]
            ).astype(np.float32)
        self._adam_table = to_device(table, self.device)
        self._table_rows = torch.zeros(k, dtype=torch.int64, device=self.device)
        self._coefficients = torch.zeros(2, k, 1, device=self.device)
        self._bias_correction, self._step_size = self._coefficients.unbind(0)
        self._eps = torch.full((), EPS, device=self.device)
        self._adam_views = [
            (params, grad, *moments, torch.empty_like(grad))
            for params, grad, moments in (
                (self.critic_params[0], self.critic_grad, self.critic_moments),
                (self.actor_params[1], self.actor_grad, self.actor_moments),
            )
        ]

        self._actor_weights = self.actor_layout.views(self.actor_params.view(2 * k, -1))
        self._critic_weights = self.critic_layout.views(self.critic_params.view(2 * k, -1))
        self._actor_online = [w[k:] for w in self._actor_weights]
        self._critic_online = [w[:k] for w in self._critic_weights]
        self._actor_grads = self.actor_layout.views(self.actor_grad)
        self._critic_grads = self.critic_layout.views(self.critic_grad)
        self._batch_size = 0
        self._act_out = torch.zeros(k, -(-act_size // SIMD_PAD) * SIMD_PAD, device=self.device)
        act_input = self._with_ones(k, obs_size + 1, 1, ones_at=-2)
        self._act_obs = act_input[:, :-1, 0]
        self._act_pass = _forward_steps(
            self._actor_online, act_input, self._hidden(self.actor_layout, k, 1, act_size)
        )

    # ----------------------------------------------------------------- parameters in and out
    @property
    def steps(self) -> np.ndarray:
        """The agents' Adam step counts ``[k]`` (int64; a copy from the device)."""
        return to_host(self.adam_steps)

    def _internal(self, layout: _Layout, flat: np.ndarray) -> torch.Tensor:
        """Host parameters ``[k, P]`` in Eq. 1 order, on the device in the internal order."""
        flat = np.asarray(flat, dtype=np.float32)
        if flat.ndim != 2 or flat.shape[1] != layout.spec.n_params:
            raise ValueError(
                f"parameters must be [k, {layout.spec.n_params}], got {tuple(flat.shape)}"
            )
        return to_device(flat.take(layout.to_internal, axis=1), self.device)

    def _paper(self, layout: _Layout, flat: torch.Tensor) -> np.ndarray:
        """Device parameters ``[k, P]`` in the internal order, on the host in Eq. 1 order
        (C-contiguous: checkpoints store it as it is)."""
        return to_host(flat).take(layout.to_paper, axis=1)

    def actor_flat(self, rows: torch.Tensor | None = None) -> np.ndarray:
        """Online Actor parameters ``[k, P_actor]`` (float32, Eq. 1 order), or ``[m,
        P_actor]`` of the agents at ``rows`` (an int64 index tensor ``[m]`` on the device:
        they are selected there, so only their parameters cross)."""
        return self._paper(self.actor_layout, _select(self.actor_params[1], rows))

    def critic_flat(self, rows: torch.Tensor | None = None) -> np.ndarray:
        """Online Critic parameters ``[k, P_critic]`` (float32, Eq. 1 order), or those of
        the agents at ``rows`` (as in :meth:`actor_flat`)."""
        return self._paper(self.critic_layout, _select(self.critic_params[0], rows))

    def state(self) -> dict[str, np.ndarray]:
        """Every learned quantity as ``[k, P]`` arrays in Eq. 1 order (for comparisons)."""
        a, c = self.actor_layout, self.critic_layout
        return {
            "actor": self.actor_flat(),
            "actor_target": self._paper(a, self.actor_params[0]),
            "actor_exp_avg": self._paper(a, self.actor_moments[0]),
            "actor_exp_avg_sq": self._paper(a, self.actor_moments[1]),
            "critic": self.critic_flat(),
            "critic_target": self._paper(c, self.critic_params[1]),
            "critic_exp_avg": self._paper(c, self.critic_moments[0]),
            "critic_exp_avg_sq": self._paper(c, self.critic_moments[1]),
        }

    def load_state(self, state: dict[str, np.ndarray], steps: np.ndarray) -> None:
        """Take every learned quantity from :meth:`state`'s arrays (``[k, P]``, Eq. 1
        order; all eight names) and the agents' Adam step counts ``steps [k]``: the learner
        then updates exactly as the one that exported them."""
        a, c = self.actor_layout, self.critic_layout
        pairs = (
            (self.actor_params[1], a, "actor"),
            (self.actor_params[0], a, "actor_target"),
            (self.actor_moments[0], a, "actor_exp_avg"),
            (self.actor_moments[1], a, "actor_exp_avg_sq"),
            (self.critic_params[0], c, "critic"),
            (self.critic_params[1], c, "critic_target"),
            (self.critic_moments[0], c, "critic_exp_avg"),
            (self.critic_moments[1], c, "critic_exp_avg_sq"),
        )
        for target, layout, name in pairs:
            target.copy_(self._internal(layout, state[name]))
        self.adam_steps.copy_(to_device(steps, self.device, torch.int64))

    def reset_agent(self, agent: int, theta: np.ndarray, omega: np.ndarray) -> None:
        """Restart slot ``agent`` from ``theta``/``omega``: targets copied from them, Adam
        moments zero, step count zero. The other agents are untouched."""
        if not 0 <= agent < self.agents:
            raise ValueError(f"agent must be in [0, {self.agents - 1}], got {agent}")
        theta = self._internal(self.actor_layout, np.asarray(theta).reshape(1, -1))[0]
        omega = self._internal(self.critic_layout, np.asarray(omega).reshape(1, -1))[0]
        self.actor_params[:, agent] = theta
        self.critic_params[:, agent] = omega
        self.actor_moments[:, agent] = 0.0
        self.critic_moments[:, agent] = 0.0
        self.adam_steps[agent] = 0

    def select(self, index: list[int]) -> LeanDDPG:
        """A learner of only the agents at ``index``, in that order: parameters, targets,
        Adam moments and step counts carried over exactly (a batch that sheds finished
        agents computes the others bit for bit as before)."""
        rows = to_device(index, self.device, torch.int64)
        out = LeanDDPG(
            self.actor_layout.spec,
            self.critic_layout.spec,
            self.actor_flat(rows),
            self.critic_flat(rows),
            learning_rate=self.learning_rate,
            gamma=self.gamma,
            tau=self.tau,
            device=self.device,
        )
        for name in ("actor_params", "critic_params", "actor_moments", "critic_moments"):
            getattr(out, name).copy_(getattr(self, name)[:, rows])
        out.adam_steps.copy_(self.adam_steps[rows])
        return out

    # ---------------------------------------------------------------------------- buffers
    def _with_ones(self, *shape: int, ones_at: int = -1) -> torch.Tensor:
        """A zero buffer whose last row (``ones_at=-2``) or column (``-1``) is ones."""
        buffer = torch.zeros(*shape, device=self.device)
        buffer.select(ones_at, shape[ones_at] - 1).fill_(1.0)
        return buffer

    def _hidden(self, layout: _Layout, m: int, batch: int, out_rows: int) -> list[torch.Tensor]:
        """Feature-major activation buffers ``[m, out + 1, B]`` (last row ones) for the hidden
        layers, then ``[m, out_rows, B]`` for the output pre-activation."""
        hidden = [self._with_ones(m, out + 1, batch, ones_at=-2) for _, out, _ in layout.blocks]
        hidden[-1] = torch.empty(m, out_rows, batch, device=self.device)
        return hidden

    def _allocate(self, batch: int) -> None:
        """Buffers for batch size ``batch`` and every view the update uses (made once)."""
        k, obs, act, device = self.agents, self.obs_size, self.act_size, self.device
        # Critic inputs, sample-major, slots: 0 (a, s, 1), 1 (mu'(s'), s', 1), 2 (mu(s), s, 1).
        x = self._with_ones(3, k, batch, act + obs + 1)
        self._fill = (x[0, :, :, :act], x[0::2, :, :, act : act + obs], x[1, :, :, act : act + obs])
        actor_h = self._hidden(self.actor_layout, 2 * k, batch, out_rows=act)
        critic_h = self._hidden(self.critic_layout, 2 * k, batch, out_rows=1)
        actor_pair = x[1:].view(2 * k, batch, -1)  # target actor reads s', online actor s
        # Actor on s and target actor on s' in one pass; mu lands in slots 2 and 1.
        self._actor_pass = _forward_steps(
            self._actor_weights, actor_pair[:, :, act:].transpose(1, 2), actor_h
        )
        self._actor_output = actor_pair[:, :, :act].transpose(1, 2)
        # Critic on (s, a) and target critic on (s', mu'(s')) in one pass.
        self._critic_pass = _forward_steps(
            self._critic_weights, x[:2].view(2 * k, batch, -1).transpose(1, 2), critic_h
        )
        # Q(s, a), Q'(s', mu'(s')), the TD target and dQ as [k, B, 1] views, like r and not_done.
        self._q, self._q_next = (q.view(k, batch, 1) for q in critic_h[-1].split(k))
        self._target = torch.empty(k, batch, 1, device=device)
        self._dq = torch.empty(k, 1, batch, device=device)
        self._dq_rows = self._dq.view(k, batch, 1)
        self._losses = torch.empty(2, k, 1, 1, device=device)  # sums: (q - y)^2 and q(s, mu)
        self._loss_views = (self._dq, self._dq_rows, *self._losses, self._losses.view(2, k))
        # sums -> means: critic MSE, actor loss -mean Q
        self._loss_scale = to_device([[1.0 / batch], [-1.0 / batch]], device, torch.float32)
        self._mean_losses = torch.empty(2, k, device=device)
        hidden = [h[:k] for h in critic_h[:-1]]
        dh = [torch.empty(k, out, batch, device=device) for _, out, _ in self.critic_layout.blocks]
        self._critic_backward = _backward_steps(
            self._critic_online, x[0], hidden, self._dq, self._critic_grads, dh
        )
        # The actor's loss through the online critic at (mu(s), s), reusing the buffers.
        self._q_actor = torch.empty(k, 1, batch, device=device)
        self._critic_actor_pass = _forward_steps(
            self._critic_online, x[2].transpose(1, 2), [*hidden, self._q_actor]
        )
        # dQ/dh at the last hidden layer is the output weight row for every sample:
        # (activation, weight row as a column, where dz goes), then products down to a.
        last = len(hidden) - 1
        self._output_row = (
            hidden[last][:, :-1],
            self._critic_online[-1][:, :, :-1].transpose(1, 2),
            dh[last],
        )
        self._row = torch.empty(k, self._output_row[1].shape[1], 1, device=device)
        self._critic_input_backward = []
        for layer in range(last, 0, -1):
            weight_t = self._critic_online[layer][:, :, :-1].transpose(1, 2)
            step = (weight_t, dh[layer], dh[layer - 1], hidden[layer - 1][:, :-1])
            self._critic_input_backward.append(step)
        self._dmu = torch.empty(k, act, batch, device=device)
        self._action_columns = (self._critic_online[0][:, :, :act].transpose(1, 2), dh[0])
        self._mu = x[2, :, :, :act].transpose(1, 2)
        dh_actor = [
            torch.empty(k, out, batch, device=device) for _, out, _ in self.actor_layout.blocks
        ]
        self._actor_backward = _backward_steps(
            self._actor_online,
            x[2, :, :, act:],
            [h[k:] for h in actor_h[:-1]],
            self._dmu,
            self._actor_grads,
            dh_actor,
        )
        self._batch_size = batch

    # ----------------------------------------------------------------------------- update
    def update(self, batch: tuple[torch.Tensor, ...]) -> tuple[np.ndarray, np.ndarray]:
        """One DDPG update of every agent on ``(s, a, r, s', not_done)``, each ``[k, B, .]``;
        returns the per-agent critic and actor losses ``[k]`` (float32)."""
        losses = to_host(self.train(batch))  # a copy: the buffer is reused next update
        return losses[0], losses[1]

    def train(self, batch: tuple[torch.Tensor, ...]) -> torch.Tensor:
        """:meth:`update` without waiting for the device: the per-agent critic and actor
        losses stay on the learner's device as a ``[2, k]`` tensor (valid until the next
        update)."""
        obs, actions, rewards, next_obs, not_done = batch
        k, size = obs.shape[:2]
        if k != self.agents:
            raise ValueError(f"batch has {k} agents, the learner {self.agents}")
        if size != self._batch_size:
            self._allocate(size)
        for buffer, values in zip(self._fill, (actions, obs, next_obs), strict=True):
            buffer.copy_(values)
        self._next_step()

        torch.sigmoid(_forward(self._actor_pass), out=self._actor_output)
        _forward(self._critic_pass)
        dq, dq_rows, critic_loss, actor_loss, losses = self._loss_views
        target = torch.addcmul(rewards, not_done, self._q_next, value=self.gamma, out=self._target)
        torch.sub(self._q, target, out=dq_rows)
        _bmm(dq, dq_rows, critic_loss)  # sum of squares per agent
        dq.mul_(2.0 / size)  # d(mean squared error)/dq
        _backward(self._critic_backward)
        self._adam(*self._adam_views[0])

        # Actor loss -mean Q(s, mu(s)) through the updated critic; critic weights stay put.
        torch.sum(_forward(self._critic_actor_pass), dim=2, keepdim=True, out=actor_loss)
        h, row, dz = self._output_row
        # d(-sum Q / B)/dh is the output weight row over -B for every sample (broadcast).
        _sigmoid_backward_(torch.mul(row, -1.0 / size, out=self._row), h, out=dz)
        for weight_t, dz, dh, s in self._critic_input_backward:
            _sigmoid_backward_(_bmm(weight_t, dz, dh), s)
        action_columns, dz = self._action_columns
        _sigmoid_backward_(_bmm(action_columns, dz, self._dmu), self._mu)
        _backward(self._actor_backward)
        self._adam(*self._adam_views[1])

        self.actor_params[0].lerp_(self.actor_params[1], self.tau)
        self.critic_params[1].lerp_(self.critic_params[0], self.tau)
        return torch.mul(losses, self._loss_scale, out=self._mean_losses)

    def _next_step(self) -> None:
        """Advance every agent's Adam step and gather its bias-corrected coefficients from
        the table (beyond its last row they no longer change), all on the device."""
        self.adam_steps += 1
        torch.clamp(self.adam_steps, max=ADAM_TABLE_STEPS, out=self._table_rows)
        coefficients = self._coefficients.view(2, self.agents)
        torch.index_select(self._adam_table, 1, self._table_rows, out=coefficients)

    def _adam(
        self,
        params: torch.Tensor,
        grad: torch.Tensor,
        exp_avg: torch.Tensor,
        exp_avg_sq: torch.Tensor,
        denom: torch.Tensor,
    ) -> None:
        """``torch.optim.Adam`` on ``[k, P]`` with per-agent bias corrections: ``param -=
        lr / bc1 * m / (sqrt(v) / sqrt(bc2) + eps)``."""
        beta1, beta2 = BETAS
        exp_avg.lerp_(grad, 1.0 - beta1)
        exp_avg_sq.mul_(beta2).addcmul_(grad, grad, value=1.0 - beta2)
        torch.sqrt(exp_avg_sq, out=denom)
        torch.addcdiv(self._eps, denom, self._bias_correction, out=denom)
        params.addcmul_(torch.div(exp_avg, denom, out=denom), self._step_size)

    # -------------------------------------------------------------------------- acting
    def act(self, obs: torch.Tensor) -> torch.Tensor:
        """Greedy actions ``[k, n]`` of the online Actors for one observation each ``[k, o]``."""
        self._act_obs.copy_(obs)
        # The output squashed in whole SIMD vectors per agent, so that no agent's actions
        # fall in a vector loop's scalar tail (other bits) depending on the batch size.
        self._act_out[:, : self.act_size] = _forward(self._act_pass)[:, :, 0]
        return torch.sigmoid(self._act_out)[:, : self.act_size]


_Product = tuple[torch.Tensor, torch.Tensor, torch.Tensor]


def _select(params: torch.Tensor, rows: torch.Tensor | None) -> torch.Tensor:
    """The agents' rows ``rows`` of ``params [k, P]`` (all of them if ``None``), on the
    device."""
    return params if rows is None else params.index_select(0, rows)


def _forward_steps(
    weights: list[torch.Tensor], inputs: torch.Tensor, buffers: list[torch.Tensor]
) -> list[_Product]:
    """``(weight, input, output)`` per layer of a sigmoid MLP on feature-major ``inputs
    [m, in + 1, B]`` (last row ones): each hidden layer writes above its buffer's ones row,
    the output layer fills its buffer."""
    steps = []
    for weight, buffer in zip(weights, buffers, strict=True):
        output = buffer[:, :-1] if len(steps) < len(weights) - 1 else buffer
        steps.append((weight, inputs, output))
        inputs = buffer
    return steps


def _forward(steps: list[_Product]) -> torch.Tensor:
    """Run :func:`_forward_steps`' products (sigmoid after each hidden layer, in place);
    returns the output layer's pre-activation ``[m, out, B]``."""
    for weight, inputs, output in steps[:-1]:
        _bmm(weight, inputs, output).sigmoid_()
    weight, inputs, output = steps[-1]
    return _bmm(weight, inputs, output)


def _backward_steps(
    weights: list[torch.Tensor],
    x: torch.Tensor,
    hidden: list[torch.Tensor],
    dz: torch.Tensor,
    grads: list[torch.Tensor],
    scratch: list[torch.Tensor],
) -> list[tuple[torch.Tensor, ...]]:
    """Views for :func:`_backward`: per layer from the last, ``(dz, input^T, gradient,
    weight^T without the bias, dh below, activation below)``, then ``(dz, x, gradient)`` for
    the first layer (``x [m, B, in + 1]`` sample-major). A gradient is a ``(view into the
    flat gradient, buffer the product is written to)`` pair: the per-layer views of ``m > 1``
    agents are not contiguous, and BLAS may then take another path than for one agent's
    (contiguous) view, so those products go through a contiguous buffer and a copy."""

    def target(grad: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return grad, grad if grad.is_contiguous() else torch.empty_like(grad.contiguous())

    steps = []
    for layer in range(len(weights) - 1, 0, -1):
        h = hidden[layer - 1]
        below = scratch[layer - 1]
        weight_t = weights[layer][:, :, :-1].transpose(1, 2)
        steps.append((dz, h.transpose(1, 2), target(grads[layer]), weight_t, below, h[:, :-1]))
        dz = below
    steps.append((dz, x, target(grads[0])))
    return steps


def _backward(steps: list[tuple[torch.Tensor, ...]]) -> None:
    """Weight gradients (bias included: the ones row) of a sigmoid MLP from the output
    pre-activation's gradient, reusing the kept activations; see :func:`_backward_steps`."""
    for dz, inputs_t, grad, weight_t, dh, s in steps[:-1]:
        _gradient(dz, inputs_t, grad)
        if weight_t.shape[2] == 1:  # a one-unit layer: an outer product, cheaper as a product
            torch.mul(weight_t, dz, out=dh)
        else:
            _bmm(weight_t, dz, dh)
        _sigmoid_backward_(dh, s)
    dz, x, grad = steps[-1]
    _gradient(dz, x, grad)


def _gradient(dz: torch.Tensor, inputs_t: torch.Tensor, grad: tuple[torch.Tensor, ...]) -> None:
    """A layer's weight gradient ``dz @ input^T`` into its view of the flat gradient."""
    view, buffer = grad
    _bmm(dz, inputs_t, buffer, reduces_batch=True)
    if buffer is not view:
        view.copy_(buffer)


def _bmm(
    a: torch.Tensor, b: torch.Tensor, out: torch.Tensor, reduces_batch: bool = False
) -> torch.Tensor:
    """``a @ b`` per agent (``[m, r, n] @ [m, n, c]``) into ``out``, with every agent's
    result independent of how many agents share the batch. BLAS picks other kernels, and so
    other summation orders, by batch count for one-column products and for one-row products
    that sum over the minibatch (``reduces_batch``: a one-unit layer's weight gradient);
    those are written as an elementwise product and a sum (measured: the others are
    batch-invariant), so a search gives the same bits alone or in any lockstep batch."""
    if a.shape[1] == 1 and reduces_batch:
        return torch.sum(a.transpose(1, 2) * b, dim=1, keepdim=True, out=out)
    if b.shape[2] == 1:
        return torch.sum(a * b.transpose(1, 2), dim=2, keepdim=True, out=out)
    return torch.bmm(a, b, out=out)


def _sigmoid_backward_(
    grad: torch.Tensor, s: torch.Tensor, out: torch.Tensor | None = None
) -> torch.Tensor:
    """``grad * s * (1 - s)``, the sigmoid's derivative from its kept output ``s``, in one
    pass (ATen's ``sigmoid_backward`` kernel), into ``out`` or in place into ``grad``."""
    return torch.ops.aten.sigmoid_backward.grad_input(
        grad, s, grad_input=grad if out is None else out
    )
