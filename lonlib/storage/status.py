"""How far an experiment is: per run and per p, from the stored trials, the manifest and the
in-flight checkpoints' metadata (what ``lonlib status`` and the analysis read; no torch)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from lonlib.storage.digests import check_readable
from lonlib.storage.inflight import inflight_checkpoints
from lonlib.storage.layout import config_of_manifest, read_manifest, trials_path
from lonlib.storage.trials import read_trials, replay_trials


def run_status(out: str | Path) -> pd.DataFrame:
    """One row per planned run: ``state`` (finished, started, not started) and why it
    ended; local searches stored and accepted; ``failures``, the rejections in a row that
    count towards the tolerance T; the best fitness; ``in_flight`` (a search of the run is
    saved in a lockstep checkpoint, :mod:`lonlib.experiment.checkpoints`) and its
    ``in_flight_steps``
    (env steps; the most any checkpoint holds); and ``fitness``, the chain of stored fitness
    values with ``x`` after each rejected one. Reads the trials, the manifest and the seal's
    digests of the rows: tables that no longer match their seal are read all the same, with
    a :class:`~lonlib.storage.digests.TamperedDataWarning` naming the file (an unsealed
    folder: an ``UnsealedDataWarning``); an optimum file that is missing or damaged shows
    when the run resumes or ``lonlib verify`` runs, not here."""
    out = Path(out)
    manifest = read_manifest(out)
    check_readable(out, manifest, "lonlib status", refuse=False, files=False)
    config = config_of_manifest(manifest, out / "manifest.json")
    saved: dict[tuple[float, int], int] = {}
    for checkpoint in inflight_checkpoints(out):
        for key, steps in zip(checkpoint.runs, checkpoint.steps, strict=True):
            saved[key] = max(saved.get(key, 0), steps)
    rows = []
    for p in config.perturbations:
        bh = config.basin_hopping(p)
        for run in range(config.runs):
            path = trials_path(out, p, run)
            state = replay_trials(read_trials(path), bh) if path.exists() else None
            trials = state.trials if state is not None else []
            rows.append(
                {
                    "p": p,
                    "run": run,
                    "state": "not started"
                    if state is None
                    else ("finished" if state.finished else "started"),
                    "end_reason": (state.end_reason if state is not None else None) or "",
                    "local_searches": len(trials),
                    "accepted": sum(t.accepted for t in trials),
                    "failures": state.failures if state is not None else 0,
                    "best_fitness": trials[state.incumbent_index].fitness
                    if state is not None and state.incumbent_index >= 0
                    else float("nan"),
                    "in_flight": (p, run) in saved,
                    "in_flight_steps": saved.get((p, run), 0),
                    "fitness": " ".join(
                        f"{t.fitness:.3f}{'' if t.accepted else 'x'}" for t in trials
                    ),
                }
            )
    return pd.DataFrame(rows)


def experiment_status(out: str | Path) -> pd.DataFrame:
    """Per p: runs finished, started (interrupted or running), not started; local searches,
    best fitness; searches in flight saved in lockstep checkpoints
    (:mod:`lonlib.experiment.checkpoints`)
    and their env steps. Reads the manifest for the planned runs (:func:`run_status`, summed
    per p)."""
    runs = run_status(out)
    rows = []
    for p, group in runs.groupby("p", sort=False):
        state = group["state"]
        rows.append(
            {
                "p": p,
                "runs": len(group),
                "finished": int((state == "finished").sum()),
                "started": int((state == "started").sum()),
                "not_started": int((state == "not started").sum()),
                "local_searches": int(group["local_searches"].sum()),
                "best_fitness": group["best_fitness"].max(),
                "saved_in_flight": int(group["in_flight"].sum()),
                "saved_env_steps": int(group["in_flight_steps"].sum()),
            }
        )
    return pd.DataFrame(rows)
