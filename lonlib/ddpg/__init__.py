"""DDPG as the local search F(theta, omega, e, h): networks, random streams, replay buffers,
the reference and the lean learner, the slot trainer, their host-device copies (torch)."""

from lonlib.ddpg.devices import TransferLog, cpu_as_device
from lonlib.ddpg.lean import LeanDDPG
from lonlib.ddpg.learner import Learner, learner_class, make_learner
from lonlib.ddpg.reference import AutogradDDPG
from lonlib.ddpg.replay import ReplayBuffer
from lonlib.ddpg.search import local_search, local_search_batch
from lonlib.ddpg.search_interface import ddpg_local_search, local_optimum
from lonlib.ddpg.slots import HISTORY_COLUMNS, EpisodeRecord, LocalSearchResult
from lonlib.ddpg.streams import CounterStreams
from lonlib.ddpg.trainer import SlotTrainer, check_device, greedy_scores

__all__ = [
    "AutogradDDPG",
    "CounterStreams",
    "EpisodeRecord",
    "HISTORY_COLUMNS",
    "LeanDDPG",
    "Learner",
    "LocalSearchResult",
    "ReplayBuffer",
    "SlotTrainer",
    "TransferLog",
    "check_device",
    "cpu_as_device",
    "ddpg_local_search",
    "greedy_scores",
    "learner_class",
    "local_optimum",
    "local_search",
    "local_search_batch",
    "make_learner",
]
