"""A stored experiment as the analysis reads it (:class:`StoredExperiment`: its configuration and
trials, loaded once) and each p of it (:class:`Landscape`: its trials, its LON, the fitness of
its sinks and of all its optima, and each run's best), each p's LON built once."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import networkx as nx
import numpy as np
import pandas as pd

from lonlib.config import ExperimentConfig
from lonlib.lon.graphs import build_lon, sinks
from lonlib.storage.digests import loaded_inputs
from lonlib.storage.layout import stored_config
from lonlib.storage.trials import read_finished_trials


@dataclass(frozen=True)
class Landscape:
    """What the claims need of one p: its trials, its LON (:func:`~lonlib.lon.graphs.build_lon`,
    maximised), the fitness of its sinks and of all its optima, and each run's best
    (final) fitness."""

    p: float
    graph: nx.DiGraph
    sink_fitness: np.ndarray
    optima_fitness: np.ndarray
    run_best: np.ndarray
    trials: pd.DataFrame

    @property
    def labelled(self) -> bool:
        """True when some optimum carries a behaviour label (lonlib.task.behaviour)."""
        return any(label for _, label in self.graph.nodes(data="label", default=""))


def landscapes(trials: pd.DataFrame, fitness_tolerance: float = 1e-9) -> dict[float, Landscape]:
    """One :class:`Landscape` per stored p, in increasing p."""
    out = {}
    for p, group in trials.groupby("p", sort=True):
        graph = build_lon(group, "max", fitness_tolerance)
        fitness = dict(graph.nodes(data="fitness"))
        out[float(p)] = Landscape(
            p=float(p),
            graph=graph,
            sink_fitness=np.array([fitness[n] for n in sinks(graph)], float),
            optima_fitness=np.array(list(fitness.values()), float),
            run_best=np.array([fitness[n] for n in graph.graph["run_ends"].values()], float),
            trials=group,
        )
    return out


@dataclass
class StoredExperiment:
    """An experiment folder loaded once: its stored configuration, its finished trials and
    (:attr:`landscapes`, on first use) one :class:`Landscape` per p, the LON of each p built
    once at ``fitness_tolerance`` for every figure, table and claim."""

    folder: Path
    config: ExperimentConfig
    trials: pd.DataFrame
    fitness_tolerance: float = 1e-9
    inputs: str | None = None
    """The digest of the trials as loaded (:func:`lonlib.storage.digests.loaded_inputs`):
    what the figures drawn from them are sealed as drawn from (None: the trials as sealed
    when the figures are)."""

    @classmethod
    def load(cls, folder: str | Path, fitness_tolerance: float = 1e-9) -> StoredExperiment:
        """The experiment stored in ``folder`` (its manifest's configuration, its trials)."""
        folder = Path(folder)
        trials = read_finished_trials(folder)
        config = stored_config(folder)
        return cls(folder, config, trials, fitness_tolerance, loaded_inputs(folder, trials))

    @cached_property
    def landscapes(self) -> dict[float, Landscape]:
        """One :class:`Landscape` per stored p, in increasing p (built on first use)."""
        return landscapes(self.trials, self.fitness_tolerance)
