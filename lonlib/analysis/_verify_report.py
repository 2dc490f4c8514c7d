"""What ``lonlib verify`` found (:mod:`lonlib.analysis.verify`): each check that did not
hold, and the report of a whole experiment."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from lonlib.storage.result_path import RESULT_PATH_VERSION


@dataclass(frozen=True)
class Finding:
    """One check that did not hold (or could not run) for one trial or recording."""

    severity: str  # "error", "warning" or "info" (what applied, e.g. exact or tolerant replay)
    check: str  # fitness, descriptor, label, consistency, actor, recording, version
    p: float | None
    run: int | None
    index: int | None
    message: str

    def __str__(self) -> str:
        where = "" if self.p is None else f"p={self.p:g} run {self.run} index {self.index}: "
        return f"{self.severity}: [{self.check}] {where}{self.message}"


@dataclass
class VerifyReport:
    """What :func:`verify_experiment` found."""

    folder: Path
    trials: int = 0  # trials in the experiment
    replayed: int = 0  # trials whose Actor was stored and replayed
    starts: int = 0  # trials whose start was rebuilt and scored
    recordings: int = 0  # recordings checked
    current_version: bool = True  # every session ran the current result-path version
    sealed: bool = True  # the folder has a seal (lonlib.storage.digests)
    recordings_checked: bool = True  # the recordings were replayed and their index checked
    descriptor_checked: bool = True  # a Gymnasium task's descriptor imported (its b_* replayed)
    findings: list[Finding] = field(default_factory=list)

    @property
    def errors(self) -> list[Finding]:
        """Findings that fail the verification."""
        return [f for f in self.findings if f.severity == "error"]

    @property
    def warnings(self) -> list[Finding]:
        """Findings reported without failing it."""
        return [f for f in self.findings if f.severity == "warning"]

    @property
    def ok(self) -> bool:
        """True when no check failed (warnings allowed)."""
        return not self.errors

    @property
    def complete(self) -> bool:
        """True when every stored number could be replayed: False when a Gymnasium task's
        descriptor does not import here (its stored behaviour is then unchecked; a warning
        says why). ``lonlib verify`` fails an incomplete verification."""
        return self.descriptor_checked

    def counts(self) -> Counter:
        """Findings by (severity, check)."""
        return Counter((f.severity, f.check) for f in self.findings)

    def summary(self) -> str:
        """A few lines for the terminal: what was checked and what did not hold."""
        lines = [
            f"{self.folder}: {self.trials} trials, {self.replayed} replayed from their stored "
            f"Actor, {self.starts} starts rebuilt and scored, {self.recordings} recordings"
        ]
        if not self.current_version:
            lines.append(
                f"sampled under another result-path version than this code's "
                f"({RESULT_PATH_VERSION}): mismatches are reported as warnings"
            )
        if not self.sealed:
            lines.append(f"unsealed: `lonlib verify {self.folder} --seal` seals it if it verifies")
        for (severity, check), count in sorted(self.counts().items()):
            lines.append(f"  {severity}s [{check}]: {count}")
        if not self.ok:
            lines.append(f"verify: FAILED ({len(self.errors)} errors)")
        elif not self.complete:
            lines.append(
                "verify: INCOMPLETE (no error, but the stored behaviour was not replayed: its "
                "task.descriptor does not import here)"
            )
        else:
            lines.append("verify: OK")
        return "\n".join(lines)


__all__ = [
    "Finding",
    "VerifyReport",
]
