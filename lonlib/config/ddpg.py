"""DDPG's hyperparameters (the paper's ``h``) and their static checks; no torch (whether
this machine computes on a device is :func:`lonlib.ddpg.trainer.check_device`'s question)."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from lonlib.config.scoring import Scoring
from lonlib.util.validation import (
    check_choice,
    check_field_types,
    check_range,
)

LEARNERS = ("lean", "autograd")  # DDPG's update: lonlib.ddpg.lean, lonlib.ddpg.reference
# torch's device types (a device is "type" or "type:index"), checked here without torch;
# lonlib.ddpg.trainer.check_device asks torch whether this machine computes on one
TORCH_DEVICE_TYPES = (
    "cpu",
    "cuda",
    "mps",
    "xpu",
    "meta",
    "hip",
    "ve",
    "fpga",
    "maia",
    "xla",
    "lazy",
    "vulkan",
    "ipu",
    "mkldnn",
    "opengl",
    "opencl",
    "ideep",
    "hpu",
    "mtia",
    "privateuseone",
)
TORCH_DEVICE = re.compile(rf"({'|'.join(TORCH_DEVICE_TYPES)})(:\d+)?")


@dataclass(frozen=True)
class DDPGConfig:
    """DDPG hyperparameters (the paper's ``h``). Paper values: buffer, batch, noise, lr,
    gamma. Ours: tau, the warm-up and the step budget (README, "DDPG local search").

    ``plateau_tiebreak``: when the greedy fitness ties the best so far, a higher greedy
    reward return counts as progress (it keeps the parameters and resets the patience), so
    a search on a zero-fitness plateau is judged by whether it is still getting closer.

    ``count_start``: the start parameters (and greedy evaluations during the warm-up, when
    the Actor is still the start) are candidates for the returned optimum. Off by default:
    a basin-hopping trial is then accepted only if learning produced the optimum.

    ``eval_seed``: the random stream of the greedy evaluations' start noise (used only when
    the environment's ``initial_noise`` > 0). It is the same for every policy and every
    trial, so an optimum's fitness is a function of its parameters alone.

    ``fitness_estimate``: what a greedy evaluation scores and so what the search keeps,
    returns and Algorithm 2 compares: ``nominal`` (Algorithm 1 from the fixed start, the
    paper) or ``robust`` (its mean over ``robust_starts`` starts perturbed by
    U[-``robust_noise``, ``robust_noise``], drawn from ``robust_seed``, the same for every
    policy; :class:`lonlib.config.scoring.Scoring`). Every trial records both, whichever is used.

    ``judge_every``: how often the search's policy is greedy-evaluated (judged: scored, a
    candidate for the returned optimum). 0 (default) judges it after every training episode;
    ``J`` > 0 judges it only after the episodes whose end crosses a multiple of ``J`` env
    steps of the search (above ``max_steps``: only the Actor at the stop is judged). The
    paper does not say when its local search evaluates; judging costs one greedy rollout
    (up to ``steps`` env steps) per judged policy, and training episodes end every 30-150
    env steps early on, so long searches set about ``steps``. The patience counts from the
    last judged improvement, so ``judge_every`` must be below ``patience_steps`` unless
    ``min_steps`` = ``max_steps`` (:func:`check_judging`).

    ``device`` and ``threads`` say where the computation runs, not what it computes.

    ``update``: ``"lean"`` (:class:`lonlib.ddpg.lean.LeanDDPG`, hand-written passes, the
    default) or ``"autograd"`` (:mod:`lonlib.ddpg.reference`, the reference); same algorithm.
    """

    buffer_size: int = 40_000
    """Replay buffer capacity, transitions (paper: 40 000)."""
    batch_size: int = 2000
    """Minibatch size, sampled every environment step (paper: 2000)."""
    noise_std: float = 0.1
    """Standard deviation of the Gaussian action noise (paper: 0.1)."""
    learning_rate: float = 1e-3
    """Adam's learning rate of Actor and Critic (paper: 0.001)."""
    gamma: float = 0.99
    """Discount factor (paper: 0.99)."""
    tau: float = 0.005
    """Soft target-update rate (ours: 0.005)."""
    warmup_steps: int = 2000
    """Environment steps with random actions before training starts."""
    max_steps: int = 150_000
    """Budget of one local search, environment steps."""
    min_steps: int = 60_000
    """A local search never stops for patience before this many steps."""
    patience_steps: int = 40_000
    """Stop when this many steps bring no new best greedy fitness."""
    eval_seed: int = 0
    """Random stream of the greedy evaluations' start noise (the same for every policy)."""
    fitness_estimate: str = "nominal"
    """What a greedy evaluation scores: ``nominal`` (Algorithm 1) or ``robust``."""
    robust_starts: int = 8
    """Perturbed starts of the ``robust`` estimate (and of the conditioning)."""
    robust_noise: float = 0.01
    """Half-width of the ``robust`` starts' uniform perturbation."""
    robust_seed: int = 0
    """Random stream of the ``robust`` starts."""
    plateau_tiebreak: bool = False
    """On equal greedy fitness, a higher greedy return counts as progress."""
    count_start: bool = False
    """The start parameters are candidates for the returned optimum."""
    judge_every: int = 0
    """Env steps between greedy evaluations (0: after every training episode)."""
    device: str = "cpu"
    """Where DDPG computes (``cpu``, ``cuda[:i]``); not what it computes."""
    threads: int = 1
    """torch CPU threads; not what it computes."""
    update: str = "lean"
    """The learner: ``lean`` (hand-written passes, default) or ``autograd`` (reference)."""

    @property
    def scoring(self) -> Scoring:
        """How greedy evaluations score a policy (:class:`lonlib.config.scoring.Scoring`)."""
        return Scoring(
            estimate=self.fitness_estimate,
            starts=self.robust_starts,
            noise=self.robust_noise,
            seed=self.robust_seed,
            eval_seed=self.eval_seed,
        )

    def __post_init__(self) -> None:
        check_field_types(self)
        for name in ("buffer_size", "batch_size", "warmup_steps", "max_steps", "patience_steps"):
            check_range(name, getattr(self, name), 1)
        check_range("min_steps", self.min_steps, 0)
        check_range("eval_seed", self.eval_seed, 0, 2**63 - 1)
        check_range("threads", self.threads, 1, 256)
        check_range("judge_every", self.judge_every, 0, 2**62)
        # a search stores one transition per env step: 1e8 is far past any budget run here
        check_range("buffer_size", self.buffer_size, 1, MAX_BUFFER_SIZE)
        check_range("noise_std", self.noise_std, 0.0, 1.0)
        check_range("learning_rate", self.learning_rate, 0.0, 1.0, low_open=True)
        check_range("gamma", self.gamma, 0.0, 1.0)
        check_range("tau", self.tau, 0.0, 1.0, low_open=True)
        if self.warmup_steps > self.max_steps:
            raise ValueError(
                f"warmup_steps must be <= max_steps ({self.max_steps}) so that DDPG trains "
                f"at least once, got {self.warmup_steps!r}"
            )
        check_choice("update", self.update, LEARNERS)
        _ = self.scoring  # validates fitness_estimate and the robust_* fields by name
        if self.min_steps > self.max_steps:
            raise ValueError(
                f"min_steps must be <= max_steps ({self.max_steps}), got {self.min_steps!r}"
            )
        if not TORCH_DEVICE.fullmatch(self.device):
            raise ValueError(
                f"device {self.device!r} is not a torch device: expected a device type "
                f"({', '.join(TORCH_DEVICE_TYPES)}), optionally with ':index'"
            )


MAX_BUFFER_SIZE = 100_000_000
"""The largest replay buffer (transitions) a configuration may ask for: 2,500 times the
paper's 40,000 and 670 times its 150,000-step budget; ~18 GB on two carts."""

EXECUTION_ONLY_DDPG_FIELDS = ("device", "threads")  # where DDPG runs, not what it computes


def check_judging(hp: DDPGConfig) -> None:
    """ValueError, naming both fields, if ``hp.judge_every`` leaves the patience no room: the
    patience counts from the last judged improvement, so where it can stop a search
    (``min_steps`` < ``max_steps``) a policy must be judged more often than every
    ``patience_steps``. Checked where the stopping rule is final: by an experiment's
    configuration and by the trainer (a calibration study replaces the budget first)."""
    if hp.judge_every >= hp.patience_steps and hp.min_steps < hp.max_steps:
        raise ValueError(
            f"ddpg.judge_every must be < ddpg.patience_steps ({hp.patience_steps}) when "
            "patience can stop a search (min_steps < max_steps): the patience counts from the "
            f"last judged improvement, got {hp.judge_every!r}"
        )


# Minibatch sizes that keep a batched agent's update bit-identical to its update alone
# (measured: sizes that are not a multiple of 4 take other vector-loop paths by batch).
BATCH_MULTIPLE = 8


def check_batch_size(hp: DDPGConfig, agents: int) -> None:
    """Refuse, naming ``batch_size``, a minibatch size that would make a batched agent's
    bits depend on its batch (only when more than one agent trains)."""
    if agents > 1 and hp.batch_size % BATCH_MULTIPLE:
        raise ValueError(
            f"batch_size must be a multiple of {BATCH_MULTIPLE} to train agents together "
            f"(other sizes make an agent's bits depend on its batch), got {hp.batch_size}"
        )


def without_default_judging(ddpg: dict[str, Any]) -> dict[str, Any]:
    """DDPG settings (plain data) without ``judge_every`` where it is 0: results stored before
    the field existed judged every episode, which is what 0 means, so they stay comparable."""
    if ddpg.get("judge_every") == 0:
        ddpg.pop("judge_every")
    return ddpg
