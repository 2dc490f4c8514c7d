"""One experiment folder -> the paper's analysis: figures, metrics, peaks, recordings.

The notebooks call these functions; ``make reproduce`` runs the notebooks. Outputs go to
``<experiment>/figures/`` and ``<experiment>/recordings/`` (never overwriting anything but
the figures and tables derived here), each written under a temporary name, sealed ahead, then
renamed into place (:mod:`lonlib.storage.outputs`): a kill never leaves a folder that reads
as tampered, and the same command again completes it.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from lonlib.analysis.claims import (
    BEHAVIOUR_NODE_EPSILON,
    SPARSE_MAX_SHARE,
    claim_d_curve,
    claims_of_landscapes,
    peaks_of_landscapes,
)
from lonlib.analysis.claims_power import power_table
from lonlib.analysis.claims_report import write_claims
from lonlib.analysis.claims_rescored import FILES as ROBUST_CLAIMS_FILES
from lonlib.analysis.claims_rescored import write_robust_claims
from lonlib.analysis.conditioning import (
    conditioning_by_label,
    edges_no_longer_improving,
    peaks_under_both_aggregations,
    replay_optima,
    retention_curve,
    stored_actors,
)
from lonlib.analysis.holding import COLUMNS as HOLDING_COLUMNS
from lonlib.analysis.holding import holding_table, needed_columns
from lonlib.analysis.landscape import StoredExperiment
from lonlib.analysis.peaks import compare_with_paper, detect_peaks
from lonlib.analysis.plots import (
    claim_d_curve_plot,
    fitness_histogram,
    lon_3d,
    lon_3d_interactive,
    nominal_beside_robust,
    optima_boxplot,
    retention_plot,
    save_html,
    sensitivity,
)
from lonlib.analysis.recordings import record, recording_name, recordings_index
from lonlib.analysis.summary import experiment_summary
from lonlib.analysis.task_recordings import record_task
from lonlib.config import ExperimentConfig
from lonlib.lon.behaviour import behaviour_table, behavioural_lon
from lonlib.lon.graphs import build_lon, node_id, sinks
from lonlib.lon.metrics import lon_metrics
from lonlib.storage.digests import check_experiment_seal, is_sealed
from lonlib.storage.layout import optimum_path, read_manifest, stored_config
from lonlib.storage.outputs import publish_figures, publish_recordings, staging_folder
from lonlib.storage.trials import read_finished_trials, read_optimum
from lonlib.task.behaviour import descriptors_of
from lonlib.task.interface import task_of
from lonlib.util.figures import save_png
from lonlib.util.labels import p_label
from lonlib.util.validation import check_range


def load_experiment(
    folder: str | Path, check_seal: bool = True, reader: str = "lonlib analyse"
) -> tuple[ExperimentConfig, pd.DataFrame]:
    """The stored configuration and all trials of an experiment folder (refused when they
    no longer match the folder's seal, naming ``reader``, the command that reads, unless
    ``check_seal`` is False: ``lonlib verify``)."""
    folder = Path(folder)
    trials = read_finished_trials(folder, check_seal=check_seal, reader=reader)
    return stored_config(folder), trials


@dataclass
class Analysis:
    """What :func:`analyse` produced: tables, the files it wrote, the matplotlib figures
    (saved as PNG) and the interactive 3-D LONs (plotly, saved as HTML), by file stem."""

    metrics: pd.DataFrame
    peaks: pd.DataFrame
    behaviours: pd.DataFrame = field(default_factory=pd.DataFrame)  # typical behaviours per p
    behavioural_metrics: pd.DataFrame = field(default_factory=pd.DataFrame)
    claims: pd.DataFrame = field(default_factory=pd.DataFrame)  # the paper's claims, verdicts
    claim_peaks: pd.DataFrame = field(default_factory=pd.DataFrame)  # peaks at the claims' p
    claim_d_curve: pd.DataFrame = field(default_factory=pd.DataFrame)  # claim d over epsilon
    power: pd.DataFrame = field(default_factory=pd.DataFrame)  # runs each claim needs, cost
    summary: pd.DataFrame = field(default_factory=pd.DataFrame)  # how far, what found, per p
    files: list[Path] = field(default_factory=list)
    figures: dict[str, plt.Figure] = field(default_factory=dict)
    replayed: pd.DataFrame = field(default_factory=pd.DataFrame)  # stored Actors replayed
    retention: pd.DataFrame = field(default_factory=pd.DataFrame)  # keep share over noise
    conditioning: pd.DataFrame = field(default_factory=pd.DataFrame)  # per behaviour label
    peaks_aggregations: pd.DataFrame = field(default_factory=pd.DataFrame)  # all vs mean
    claims_robust: pd.DataFrame = field(default_factory=pd.DataFrame)  # re-scored: robust mean
    claims_side_by_side: pd.DataFrame = field(default_factory=pd.DataFrame)  # nominal | robust
    interactive: dict[str, Any] = field(default_factory=dict)
    holding: pd.DataFrame = field(default_factory=pd.DataFrame)  # the optima that hold their rods
    skipped: str = ""  # what does not apply to the experiment's task, in one line


def analyse(
    experiment: str | Path | StoredExperiment,
    seed: int = 0,
    fitness_tolerance: float = 1e-9,
    bins: int = 50,
    close_figures: bool = False,
    conditioning: bool = True,
) -> Analysis:
    """Figures 2-5, the 3-D LON (PNG + HTML), peaks beside the paper's, metrics per p, the
    paper's claims tested (``claims.csv``, ``claims.md``: :mod:`lonlib.analysis.claims`; claim d's
    curve over epsilon, ``claim_d_curve.csv`` and ``.png``; the runs each claim needs and
    their cost, ``power.csv``: :mod:`lonlib.analysis.claims_power`), the
    experiment's summary per p (``summary.csv``: :mod:`lonlib.analysis.summary`), and a
    sensitivity view when more than two p values are present. Reads the stored runs and
    writes only under ``<folder>/figures/``: every file under a temporary name first, then
    sealed ahead and renamed into place (:func:`lonlib.storage.outputs.publish_figures`).

    ``close_figures`` closes each matplotlib figure once saved (it stays in the result and
    can still be displayed), so a notebook's inline backend does not show every figure at
    the end of the cell that called this. ``conditioning`` adds the nodes' conditioning
    (replaying every stored Actor: about a minute for 40 optima on one core), the claims
    on the LONs re-scored with the robust mean beside the nominal ones
    (``claims_robust.csv``, ``claims_nominal_robust.csv`` and ``.md``) and the optima that
    hold their rods (``holding.csv``: :mod:`lonlib.analysis.holding`).

    ``experiment``: a folder, or a :class:`~lonlib.analysis.landscape.StoredExperiment`
    loaded from one (at ``fitness_tolerance``, which it then carries): each p's LON is built
    once, for the figures, the claims and the conditioning."""
    if not isinstance(experiment, StoredExperiment):
        experiment = StoredExperiment.load(experiment, fitness_tolerance)
    with staging_folder(experiment.folder / "figures") as out:  # every file here first
        result, removed = _draw(experiment, out, seed, bins, close_figures, conditioning)
        result.files = publish_figures(
            experiment.folder, result.files, removed, staging=out, inputs=experiment.inputs
        )
    return result


def _draw(
    experiment: StoredExperiment,
    out: Path,
    seed: int,
    bins: int,
    close_figures: bool,
    conditioning: bool,
) -> tuple[Analysis, list[str]]:
    """What :func:`analyse` writes, written into ``out`` (its staging folder): the analysis
    and the names of the files an earlier analysis left that this one no longer makes."""
    folder, trials = experiment.folder, experiment.trials
    fitness_tolerance = experiment.fitness_tolerance
    result = Analysis(metrics=pd.DataFrame(), peaks=pd.DataFrame())
    removed: list[str] = []

    def save(name: str, fig: plt.Figure) -> None:
        path = save_png(fig, out / f"{name}.png")
        result.files.append(path)
        result.figures[name] = fig
        if close_figures:
            plt.close(fig)

    pendulums = experiment.config.task is None
    if not pendulums:
        result.skipped = GENERIC_TASK_SKIPS
    save("fig2_optima_boxplot", optima_boxplot(trials))
    labelled = "label" in trials
    metric_rows, peak_rows, behavioural_rows = [], [], []
    for p, land in experiment.landscapes.items():
        graph, group = land.graph, land.trials
        label = p_label(p)
        metric_rows.append({"p": p, **lon_metrics(graph)})
        name, title = f"fig3_lon_p={label}", f"3-D LON, p = {label}"
        save(name, lon_3d(graph, seed, title=title))
        result.interactive[name] = lon_3d_interactive(
            graph, seed, title=title, hover=behaviour_hover(group) if labelled else None
        )
        result.files.append(save_html(result.interactive[name], out / f"{name}.html"))
        sink_names = sinks(graph)
        sink_fitness = np.array([graph.nodes[n]["fitness"] for n in sink_names])
        optima_fitness = np.array([f for _, f in graph.nodes(data="fitness")])
        sink_labels = [graph.nodes[n]["label"] for n in sink_names] if labelled else None
        optima_labels = [d for _, d in graph.nodes(data="label")] if labelled else None
        save(
            f"fig4_sinks_p={label}",
            fitness_histogram(
                sink_fitness, f"Fitness of sinks, p = {label}", bins, labels=sink_labels
            ),
        )
        save(
            f"fig5_optima_p={label}",
            fitness_histogram(
                optima_fitness, f"Fitness of local optima, p = {label}", bins, labels=optima_labels
            ),
        )
        if labelled:
            behavioural_rows.append({"p": p, **lon_metrics(behavioural_lon(graph))})
        for what, values in (("sinks", sink_fitness), ("optima", optima_fitness)):
            table = detect_peaks(values, bins=bins)
            table = compare_with_paper(table) if pendulums else table
            peak_rows.append(table.assign(p=p, histogram=what))
    result.metrics = pd.DataFrame(metric_rows)
    result.peaks = pd.concat(peak_rows, ignore_index=True)
    result.summary = experiment_summary(folder, trials)
    tables = [("summary", result.summary), ("metrics", result.metrics), ("peaks", result.peaks)]
    if labelled:
        result.behaviours = behaviour_table(trials, fitness_tolerance)
        result.behavioural_metrics = pd.DataFrame(behavioural_rows)
        tables += [("behaviours", result.behaviours)]
        tables += [("metrics_behavioural", result.behavioural_metrics)]
    for name, table in tables:
        path = out / f"{name}.csv"
        table.to_csv(path, index=False)
        result.files.append(path)
    if not pendulums:
        return result, removed
    result.claims = claims_of_landscapes(experiment.landscapes, bins)
    result.claim_peaks = peaks_of_landscapes(experiment.landscapes, bins)
    result.claim_d_curve = claim_d_curve(trials)
    result.power = power_table()
    result.files += write_claims(
        result.claims, result.claim_peaks, out, result.power, result.claim_d_curve
    )
    if not result.claim_d_curve.empty:
        save(
            "claim_d_curve",
            claim_d_curve_plot(result.claim_d_curve, BEHAVIOUR_NODE_EPSILON, SPARSE_MAX_SHARE),
        )
    if trials["p"].nunique() > 2:
        save("sensitivity", sensitivity(result.metrics))
    if conditioning:
        _conditioning(experiment, result, save, out, bins, removed)
    return result, removed


GENERIC_TASK_SKIPS = (
    "skipped (they concern the coupled pendulums): the paper's claims a-e and its peaks, "
    "the conditioning and holding of optima, pendulum behaviour labels"
)


def _conditioning(
    experiment: StoredExperiment,
    result: Analysis,
    save: Callable[[str, plt.Figure], None],
    out: Path,
    bins: int,
    removed: list[str],
) -> None:
    """The nodes' conditioning (:mod:`lonlib.analysis.conditioning`): every stored Actor replayed
    (``replayed.csv``), nominal beside robust Figs. 4-5, the retention curve and the table
    per behaviour label; edges a re-scoring would make deteriorating; the optima that hold
    their rods. ``removed`` gets the names of the files an earlier analysis left that this
    one does not make (the robust claims, when the re-scoring is refused)."""
    folder, config, trials = experiment.folder, experiment.config, experiment.trials
    fitness_tolerance = experiment.fitness_tolerance
    replayed = replay_optima(folder, trials, config.env, config.ddpg.scoring)
    result.replayed = replayed
    # without stored Actors this warns and leaves no stale robust claims
    result.claims_robust, result.claims_side_by_side, files = write_robust_claims(
        trials, replayed, result.claims, out, bins, fitness_tolerance
    )
    result.files += files
    if not files:  # refused: no stale robust claims stay
        removed.extend(ROBUST_CLAIMS_FILES)
    described = set(needed_columns(config.env.n_carts)) <= set(trials.columns)
    result.holding = (  # empty without stored Actors or behaviour descriptors
        holding_table(folder, trials, config.env, config.ddpg.scoring)
        if described
        else pd.DataFrame(columns=list(HOLDING_COLUMNS))
    )
    result.holding.to_csv(out / "holding.csv", index=False)
    result.files.append(out / "holding.csv")
    if replayed.empty:
        return
    nodes = replayed[replayed["accepted"]]
    curves = []
    for p, group in nodes.groupby("p", sort=True):
        label = p_label(p)
        graph = experiment.landscapes[float(p)].graph
        sink_keys = {(graph.nodes[n]["run"], graph.nodes[n]["index"]) for n in sinks(graph)}
        is_sink = [(r, i) in sink_keys for r, i in zip(group["run"], group["index"], strict=True)]
        sink_rows = group[is_sink]
        save(
            f"fig4_sinks_robust_p={label}",
            nominal_beside_robust(
                sink_rows["replayed"], sink_rows["robust_mean"], f"sinks, p = {label}", bins
            ),
        )
        save(
            f"fig5_optima_robust_p={label}",
            nominal_beside_robust(
                group["replayed"], group["robust_mean"], f"optima, p = {label}", bins
            ),
        )
        _, thetas = stored_actors(folder, trials.loc[trials["accepted"] & (trials["p"] == p)])
        curves.append(
            retention_curve(
                thetas, group["replayed"].to_numpy(), config.env, scoring=config.ddpg.scoring
            ).assign(p=p)
        )
    result.retention = pd.concat(curves, ignore_index=True)
    save("retention", retention_plot(result.retention))
    result.conditioning = conditioning_by_label(nodes)
    edges = edges_no_longer_improving(trials, replayed)
    result.peaks_aggregations = peaks_under_both_aggregations(replayed, bins)
    for name, table in (
        ("replayed", replayed),
        ("peaks_aggregations", result.peaks_aggregations),
        ("retention", result.retention),
        ("conditioning", result.conditioning),
        ("edges_rescored", edges),
    ):
        path = out / f"{name}.csv"
        table.to_csv(path, index=False)
        result.files.append(path)


def slug(text: str) -> str:
    """File-name-safe form of a label: ``spinning (in phase)`` -> ``spinning-in-phase``."""
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-")


def behaviour_hover(trials: pd.DataFrame) -> dict[str, str]:
    """Node -> hover text with the main descriptor values of its stored behaviour (a
    Gymnasium task's descriptor: its label and every ``b_*`` value)."""
    if "b_end_reason" not in trials:  # not the pendulums' descriptor
        columns = [c for c in trials.columns if c.startswith("b_")]
        return {
            node_id(row["p"], row["run"], row["index"]): "<br>".join(
                [str(row["label"])] + [f"{c[2:]} {row[c]:.4g}" for c in columns]
            )
            for row in trials.to_dict("records")
            if isinstance(row.get("label"), str)
        }
    out = {}
    for row, d in zip(trials.itertuples(), descriptors_of(trials), strict=True):
        if d is None:
            continue
        rods = ", ".join(
            f"rod {i}: up {s:.0%}, {t:+.1f} turns"
            for i, (s, t) in enumerate(zip(d.upright_share, d.turns, strict=True))
        )
        out[node_id(row.p, row.run, row.index)] = (
            f"{rods}<br>end {d.end_reason.lower()} at step {d.end_step}; "
            f"cart range {d.cart_range:.2f} m<br>"
            f"robustness: mean {d.robust_mean:.3f}, min {d.robust_min:.3f}"
        )
    return out


def optima_to_record(
    trials: pd.DataFrame, bins: int = 50, fitness_tolerance: float = 1e-9
) -> pd.DataFrame:
    """The best optimum of each p, per detected sink-fitness peak the sink nearest it, and
    the best optimum of each behaviour label (one row per distinct optimum: p, run, index,
    fitness, role, behaviour). The roles: ``best`` (the best optimum of p), ``label-best``
    (the best optimum of its behaviour label) and ``sink-peak-<fitness>`` (the sink nearest
    a sink-fitness peak); a recording's name carries the role and the behaviour
    (:func:`lonlib.analysis.recordings.recording_name`)."""
    rows: dict[str, dict] = {}
    for _, group in trials.groupby("p", sort=True):
        graph = build_lon(group, "max", fitness_tolerance)
        chosen = [(max(graph.nodes, key=lambda n: graph.nodes[n]["fitness"]), "best")]
        by_label: dict[str, str] = {}
        for node, data in graph.nodes(data=True):
            behaviour = data.get("label")
            if behaviour and (
                behaviour not in by_label
                or data["fitness"] > graph.nodes[by_label[behaviour]]["fitness"]
            ):
                by_label[behaviour] = node
        chosen += [(node, "label-best") for node in by_label.values()]
        sink_nodes = sinks(graph)
        values = np.array([graph.nodes[n]["fitness"] for n in sink_nodes])
        for peak in detect_peaks(values, bins=bins)["fitness"]:
            nearest = sink_nodes[int(np.argmin(np.abs(values - peak)))]
            chosen.append((nearest, f"sink-peak-{peak:.2f}"))
        for node, role in chosen:
            data = graph.nodes[node]
            rows.setdefault(
                node,
                {
                    "p": data["p"],
                    "run": data["run"],
                    "index": data["index"],
                    "fitness": data["fitness"],
                    "role": role,
                    "behaviour": data.get("label", ""),
                },
            )
    return pd.DataFrame(list(rows.values()))


def _recording_name(row) -> str:
    """The file name ``record_optima`` gives the recording of a selected optimum."""
    behaviour = slug(row.behaviour) if row.behaviour else ""
    return recording_name(row.p, int(row.run), row.fitness, role=row.role, behaviour=behaviour)


def record_optima(folder: str | Path, bins: int = 50, limit: int = 24) -> list[Path]:
    """Rerun recordings of the selected optima under ``<experiment>/recordings/``: the
    first ``limit`` of them, every one when ``limit`` is 0."""
    check_range("limit", limit, 0)
    check_range("bins", bins, 1)
    folder = Path(folder)
    config, trials = load_experiment(folder, reader="lonlib record")
    selection = optima_to_record(trials, bins)
    if limit:
        selection = selection.head(limit)
    if is_sealed(folder):  # what the index will list must be what it listed, before any compute
        check = check_experiment_seal(folder, read_manifest(folder), figures=False)
        # a recording this command rewrites is regenerated (one that an older lonlib's
        # `record`, killed after it rewrote it in place, left unsealed); every other
        # difference, data or recording, stops it
        ours = {f"recordings/{_recording_name(r)}" for r in selection.itertuples()}
        check.problems = [(name, what) for name, what in check.problems if name not in ours]
        check.raise_if_tampered("lonlib record")
    with staging_folder(folder / "recordings") as staging:  # each recording here first
        paths: list[Path] = []
        task = None if config.task is None else task_of(config)
        for row in selection.itertuples():
            optimum = read_optimum(optimum_path(folder, row.p, int(row.run), int(row.index)))
            path = staging / _recording_name(row)
            title = f"{row.role} p={p_label(row.p)}"
            properties: dict[str, float | int | str] = {
                "p": float(row.p),
                "run": int(row.run),
                "index": int(row.index),
                "stored_fitness": float(row.fitness),
            }
            if task is None:
                record(optimum.theta, config.env, path, title, config.ddpg.scoring, properties)
            else:
                _, no_frames = record_task(task, optimum.theta, path, title, properties)
                if no_frames and not paths:
                    warnings.warn(f"recordings without frames: {no_frames}", stacklevel=2)
            paths.append(path)
        # the index the folder will hold: the recordings there, those staged in their place
        index = {**recordings_index(folder), **recordings_index(folder, files=set(paths))}
        publish_recordings(folder, paths, dict(sorted(index.items())))
    return [folder / "recordings" / path.name for path in paths]
