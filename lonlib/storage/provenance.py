"""Where a session's results came from: the locked environment, the CPU kernels, the code.

:func:`session_provenance` is what each session of an experiment records in its manifest
(:mod:`lonlib.storage.manifest`):

* ``environment``: the lock this environment was installed from (``source: lock``: the
  largest lock file under ``requirements/`` whose every pin is installed at its exact
  version, and the sha256 of that file) or, when no lock matches (a wheel install,
  ``make test-latest``, packages changed by hand), ``source: installed`` and the sha256 of
  the installed distribution set (``name==version`` lines, sorted). ``installed_sha256`` is
  always there (it also covers torch, which the lock leaves out);
* ``cpu``: :func:`lonlib.util.cpu_kernels.cpu_record` (numpy's dispatch targets, torch's CPU
  capability, ``ATEN_CPU_CAPABILITY``);
* ``result_path_version``: :data:`lonlib.storage.result_path.RESULT_PATH_VERSION`.

No torch here: the caller passes torch's capability.
"""

from __future__ import annotations

import hashlib
import re
from importlib import metadata
from pathlib import Path
from typing import Any

from lonlib.storage.result_path import RESULT_PATH_VERSION
from lonlib.util.cpu_kernels import cpu_record

# The committed locks of a checkout (an editable install): <repository>/requirements/*.txt
REQUIREMENTS = Path(__file__).resolve().parent.parent / "requirements"
PIN = re.compile(r"^([A-Za-z0-9][A-Za-z0-9._-]*)==([^\s;\\]+)")


def normalise(name: str) -> str:
    """A distribution name in the form lock files write it (PEP 503)."""
    return re.sub(r"[-_.]+", "-", name).lower()


def lock_pins(text: str) -> dict[str, str]:
    """The ``name: version`` pins of a pip requirements lock, in file order."""
    return {normalise(m[1]): m[2] for line in text.splitlines() if (m := PIN.match(line))}


def installed_versions() -> dict[str, str]:
    """Every distribution installed in this environment: ``name: version``."""
    return {normalise(d.metadata["Name"]): d.version for d in metadata.distributions()}


def lock_files(folder: Path = REQUIREMENTS) -> list[Path]:
    """The lock files in ``folder`` (requirements files with hashes), by name."""
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.glob("*.txt") if "--hash=sha256:" in p.read_text())


def environment_record(folder: Path = REQUIREMENTS) -> dict[str, Any]:
    """Which locked environment this process runs in (see the module's docstring)."""
    installed = installed_versions()
    listing = "".join(f"{name}=={installed[name]}\n" for name in sorted(installed))
    record: dict[str, Any] = {"installed_sha256": hashlib.sha256(listing.encode()).hexdigest()}
    matching = []
    for path in lock_files(folder):
        pins = lock_pins(path.read_text())
        if all(installed.get(name) == version for name, version in pins.items()):
            matching.append((len(pins), path))
    if matching:
        _, path = max(matching)
        record.update(
            source="lock",
            file=f"{folder.name}/{path.name}",
            sha256=hashlib.sha256(path.read_bytes()).hexdigest(),
        )
    else:
        record.update(source="installed", sha256=record["installed_sha256"])
    return record


def session_provenance(torch_capability: str | None) -> dict[str, Any]:
    """What a manifest session records about where its results came from."""
    return {
        "result_path_version": RESULT_PATH_VERSION,
        "environment": environment_record(),
        "cpu": cpu_record(torch_capability),
    }
