"""What the slot trainer (:mod:`lonlib.ddpg.trainer`) needs from a DDPG learner of ``k``
agents, and the two learners that provide it: :class:`~lonlib.ddpg.lean.LeanDDPG` (flat
buffers, hand-written passes, per-agent state) and the autograd reference
:class:`~lonlib.ddpg.reference.AutogradDDPG` (one optimizer for all agents: it cannot reset,
select or load one agent's state, and says so with ``per_agent_state = False``)."""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np
import numpy.typing as npt
import torch

from lonlib.config import LEARNERS, DDPGConfig
from lonlib.ddpg.lean import LeanDDPG
from lonlib.ddpg.reference import AutogradDDPG
from lonlib.task.policy import NetSpec

Params = npt.NDArray[np.float32]  # flat parameter vectors [k, P] in Eq. 1 order


class Learner(Protocol):
    """Every method and attribute the slot trainer and its checkpoints use of a learner."""

    per_agent_state: bool
    """Can one agent's state be reset (:meth:`reset_agent`), kept (:meth:`select`) and
    loaded (:meth:`load_state`, :attr:`steps`)? Refilling slots, shrinking or splitting a
    batch and checkpointing it need it; a learner without it raises ValueError there."""

    def update(self, batch: tuple[torch.Tensor, ...]) -> tuple[npt.NDArray[Any], npt.NDArray[Any]]:
        """One update on ``(s, a, r, s', not_done)``; per-agent critic and actor losses."""
        ...

    def train(self, batch: tuple[torch.Tensor, ...]) -> torch.Tensor:
        """:meth:`update` with the losses as a ``[2, k]`` tensor on the learner's device."""
        ...

    def act(self, obs: torch.Tensor) -> torch.Tensor:
        """Greedy actions ``[k, n]`` for one observation per agent ``[k, o]``."""
        ...

    def actor_flat(self, rows: torch.Tensor | None = None) -> Params:
        """Online Actor parameters ``[k, P_actor]`` in Eq. 1 order (only the agents at
        ``rows``, an int64 index tensor on the learner's device, if given)."""
        ...

    def critic_flat(self, rows: torch.Tensor | None = None) -> Params:
        """Online Critic parameters ``[k, P_critic]`` in Eq. 1 order (only ``rows``'s)."""
        ...

    def state(self) -> dict[str, Params]:
        """Every learned quantity as ``[k, P]`` arrays in Eq. 1 order."""
        ...

    @property
    def steps(self) -> npt.NDArray[np.int64]:
        """The agents' Adam step counts ``[k]``."""
        ...

    def load_state(self, state: dict[str, Params], steps: npt.NDArray[np.int64]) -> None:
        """Take every learned quantity from :meth:`state`'s arrays and the step counts."""
        ...

    def reset_agent(self, agent: int, theta: Params, omega: Params) -> None:
        """Restart agent ``agent`` from ``theta``/``omega`` (targets copied, Adam state empty)."""
        ...

    def select(self, index: list[int]) -> Learner:
        """A learner of only the agents at ``index``, in that order, carried over exactly."""
        ...


def learner_class(kind: str) -> type[LeanDDPG] | type[AutogradDDPG]:
    """The ``"lean"`` (:class:`LeanDDPG`) or ``"autograd"`` learner class; both take
    ``(actor_spec, critic_spec, thetas, omegas, *, learning_rate, gamma, tau, device)``."""
    if kind not in LEARNERS:
        raise ValueError(f"update must be one of {LEARNERS}, got {kind!r}")
    return LeanDDPG if kind == "lean" else AutogradDDPG


def make_learner(
    a_spec: NetSpec,
    c_spec: NetSpec,
    thetas: Params,
    omegas: Params,
    hp: DDPGConfig,
    device: torch.device | None = None,
) -> Learner:
    """The learner ``hp.update`` names for ``k`` agents starting from ``thetas``, ``omegas``
    (targets copied from them, Adam state empty) on ``device`` (default ``hp.device``)."""
    learner: Learner = learner_class(hp.update)(
        a_spec,
        c_spec,
        thetas,
        omegas,
        learning_rate=hp.learning_rate,
        gamma=hp.gamma,
        tau=hp.tau,
        device=torch.device(hp.device if device is None else device),
    )
    return learner
