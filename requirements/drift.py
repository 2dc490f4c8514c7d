"""Print how the running environment's versions differ from a lock (``make test-latest``).

Usage: ``python requirements/drift.py requirements/dev.txt``. Lists each locked package
whose installed version differs, and packages installed here that the lock does not hold
(torch, lonlib and the installer itself aside).
"""

from __future__ import annotations

import sys
from pathlib import Path

from lonlib.storage.provenance import installed_versions, lock_pins

NOT_LOCKED = {"torch", "lonlib", "pip"}


def drift(lock: Path) -> list[str]:
    """One line per difference between the lock and the installed distributions."""
    locked = lock_pins(lock.read_text())
    installed = installed_versions()
    lines = [
        f"  {name}: {version} in the lock, {installed.get(name, 'not installed')} here"
        for name, version in sorted(locked.items())
        if installed.get(name) != version
    ]
    extra = sorted(set(installed) - set(locked) - NOT_LOCKED)
    lines += [f"  {name}: not in the lock, {installed[name]} here" for name in extra]
    return lines


if __name__ == "__main__":
    path = Path(sys.argv[1])
    lines = drift(path)
    print(f"{len(lines)} difference(s) from {path}" + (":" if lines else ""))
    print("\n".join(lines))
