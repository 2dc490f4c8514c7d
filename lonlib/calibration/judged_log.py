"""The judged-policy log of a cell's searches (the trainer's ``on_judged``): every policy the
trainer judged, described from the judge's own traced nominal episode, kept per search and
restored from an in-flight checkpoint's plain data."""

from __future__ import annotations

from typing import Any

import numpy as np

from lonlib.config import PendulumConfig
from lonlib.task.behaviour import LABELS, describe_rollout, label
from lonlib.task.rollout import Rollout


class JudgedLog:
    """Every judged policy of a cell's searches, described: the trainer's ``on_judged``.

    Per search (the trainer's tags are the seed indices) four lists in judge order (episode
    order): the env steps at the episode's end, the nominal episode's fitness under both
    aggregations (``fitness_all``, ``fitness_mean``) and the behaviour label's index in
    :data:`lonlib.task.behaviour.LABELS`. Each is read from the judge's own traced nominal
    episode (:func:`lonlib.task.behaviour.describe_rollout`): no policy is rolled out twice.
    """

    def __init__(self, env: PendulumConfig, searches: int) -> None:
        self.env = env
        self.rows: dict[int, dict[str, list[Any]]] = {
            i: {"env_steps": [], "fitness_all": [], "fitness_mean": [], "label": []}
            for i in range(searches)
        }

    def __call__(self, judged: list[tuple[Any, Any, np.ndarray]], nominal: Rollout) -> None:
        """Log a batch of ``(tag, EpisodeRecord, flat Actor)`` described from ``nominal``,
        the judge's traced nominal episodes (row ``j``: entry ``j``)."""
        for row, (tag, record, _) in enumerate(judged):
            d = describe_rollout(nominal, self.env, row)
            rows = self.rows[int(tag)]
            rows["env_steps"].append(int(record.env_steps))
            rows["fitness_all"].append(d.fitness_all)
            rows["fitness_mean"].append(d.fitness_mean)
            rows["label"].append(LABELS.index(label(d)))

    def state(self) -> dict[str, Any]:
        """Plain data (JSON): what :meth:`restore` reads back."""
        return {str(i): rows for i, rows in self.rows.items()}

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from :meth:`state`'s data."""
        if set(state) != {str(i) for i in self.rows}:
            raise ValueError(f"judged log of searches {sorted(state)}, expected {len(self.rows)}")
        self.rows = {int(i): {k: list(v) for k, v in rows.items()} for i, rows in state.items()}


__all__ = ["JudgedLog"]
