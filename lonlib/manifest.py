"""The experiment manifest: what ``data/<experiment>/manifest.json`` records and checks.

It holds the configuration (merged over every session that added runs or p values), the
lonlib version, the git commit, package versions, the host and one entry per session. A
folder holding an experiment with a different configuration is refused.
"""

from __future__ import annotations

import dataclasses
import platform
import subprocess
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING, Any

from lonlib.store import read_json

if TYPE_CHECKING:
    from lonlib.configs import ExperimentConfig

PACKAGES = ("numpy", "torch", "gymnasium", "pandas", "pyarrow", "networkx", "igraph", "dask")


def manifest_path(out: Path) -> Path:
    """The manifest of the experiment folder ``out``."""
    return Path(out) / "manifest.json"


def _git_commit() -> str | None:
    try:
        return subprocess.run(
            ["git", "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
            cwd=Path(__file__).parent,
            timeout=5,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None


def _versions() -> dict[str, str | None]:
    out = {"python": platform.python_version()}
    for name in ("lonlib", *PACKAGES):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def updated_manifest(config: ExperimentConfig, out: Path) -> dict[str, Any]:
    """The manifest ``out`` should hold for ``config`` (new, or the stored one with this
    session added); refuses a folder holding another experiment. Writes nothing."""
    path = manifest_path(out)
    now = datetime.now(UTC).isoformat(timespec="seconds")
    if path.exists():
        manifest = read_json(path)
        stored = type(config).from_mapping(manifest["config"])
        if stored.comparable() != config.comparable():
            changed = sorted(
                k for k in config.comparable() if stored.comparable()[k] != config.comparable()[k]
            )
            raise ValueError(
                f"{out} holds an experiment with a different configuration ({changed} differ); "
                "choose another output folder or use the stored configuration"
            )
        runs = max(stored.runs, config.runs)
        perturbations = tuple(dict.fromkeys((*stored.perturbations, *config.perturbations)))
        merged = dataclasses.replace(stored, runs=runs, perturbations=perturbations)
        manifest["config"] = merged.to_dict()
        manifest.setdefault("sessions", []).append(
            {
                "started": now,
                "versions": _versions(),
                "git_commit": _git_commit(),
                # where DDPG ran this session: not configuration (results do not depend on it)
                "execution": {
                    "device": config.ddpg.device,
                    "threads": config.ddpg.threads,
                    "executor": config.executor,
                    "slots": config.slots,
                },
            }
        )
    else:
        manifest = {
            "experiment": config.name,
            "created": now,
            "config": config.to_dict(),
            "lonlib_version": _versions()["lonlib"],
            "git_commit": _git_commit(),
            "versions": _versions(),
            "host": platform.node(),
            "sessions": [{"started": now}],
        }
    return manifest
