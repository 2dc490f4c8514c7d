"""The folder layout of an experiment under ``data/<experiment>/``, in one place.

Layout::

    data/<experiment>/
        manifest.json                 configuration, lonlib version, git commit, packages, times
        p=<p>/run_<run>/trials.parquet    every local search of the run (the commit point)
        p=<p>/run_<run>/optimum_<i>.npz   optimum of local search i: theta, omega (float32,
                                      compressed); older experiments kept accepted ones only
        p=<p>/run_<run>/history_<i>.parquet  local search i's training curve (per episode)
        .inflight/                    in-flight checkpoints of lockstep batches
                                      (lonlib.storage.inflight, lonlib.experiment.checkpoints)
        p=<p>/run_<run>/.lock         held by the one process writing the run
        .manifest.lock                guards the manifest's check and update
"""

from __future__ import annotations

from pathlib import Path

from lonlib.config import ExperimentConfig
from lonlib.storage.atomic import CorruptDataError, MissingExperimentError, read_json
from lonlib.util.labels import p_label

INFLIGHT_FOLDER = ".inflight"  # in the experiment folder: in-flight checkpoints
RUN_LOCK = ".lock"  # in each run's folder: held by the one process writing the run
MANIFEST_LOCK = ".manifest.lock"  # in the experiment folder: guards manifest check + update
SAMPLING_LOCK = ".sampling.lock"  # held shared by every sampling session, exclusive to change it


Job = tuple[float, int]  # a run of an experiment: (p, run index)


def read_manifest(root: Path) -> dict:
    """The manifest of experiment folder ``root``: MissingExperimentError when nothing has
    been sampled there yet, CorruptDataError when it cannot be read."""
    path = Path(root) / "manifest.json"
    if not path.exists():
        raise MissingExperimentError(
            f"no experiment in {root} yet (no manifest.json). Sample one first: `make reproduce` "
            "(CONFIG=quick writes data/quick, CONFIG=paper data/paper), the sample_lon notebook, "
            f"or `lonlib run quick --out {root}`"
        )
    return checked_manifest(read_json(path), path)


def checked_manifest(manifest: object, path: Path) -> dict:
    """``manifest`` as read from ``path``, if it is a mapping whose ``config`` is a mapping:
    CorruptDataError naming the file otherwise (valid JSON of another shape)."""
    if not isinstance(manifest, dict):
        raise CorruptDataError(
            f"{path}: not a manifest (expected a JSON object, got {type(manifest).__name__})"
        )
    if not isinstance(manifest.get("config"), dict):
        raise CorruptDataError(f"{path}: not a manifest (its 'config' is not a JSON object)")
    return manifest


def run_dir(root: Path, p: float, run: int) -> Path:
    """Folder of run ``run`` at perturbation strength ``p``."""
    return Path(root) / f"p={p_label(p)}" / f"run_{run:04d}"


def trials_path(root: Path, p: float, run: int) -> Path:
    """The trials table of one run."""
    return run_dir(root, p, run) / "trials.parquet"


def optimum_path(root: Path, p: float, run: int, index: int) -> Path:
    """The parameters of accepted local search ``index`` of one run."""
    return run_dir(root, p, run) / f"optimum_{index:04d}.npz"


def history_path(root: Path, p: float, run: int, index: int) -> Path:
    """The per-episode training record of local search ``index`` of one run."""
    return run_dir(root, p, run) / f"history_{index:04d}.parquet"


def stored_config(root: Path) -> ExperimentConfig:
    """The configuration an experiment folder was sampled with, from its manifest; a bad
    stored value (``tolerance: NaN``, a key this code does not know) is CorruptDataError
    naming ``manifest.json`` and the field."""
    return config_of_manifest(read_manifest(root), Path(root) / "manifest.json")


def config_of_manifest(manifest: dict, path: Path) -> ExperimentConfig:
    """:func:`stored_config` of an already read manifest (``path`` names it in errors)."""
    try:
        return ExperimentConfig.from_mapping(manifest["config"])
    except (ValueError, TypeError, KeyError) as error:
        raise CorruptDataError(f"{path}: its stored configuration is not valid: {error}") from None
