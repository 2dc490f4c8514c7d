"""The static types of the slot trainer's modules (``[tool.mypy]`` in pyproject.toml, strict):
among them that the engine calls nothing of a learner that :class:`lonlib.ddpg.learner.Learner`
does not list, and that both learners provide all of it."""

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def test_the_strict_modules_type_check():
    pytest.importorskip("mypy", reason="mypy is in the dev lock (make lock && make setup)")
    done = subprocess.run(
        [sys.executable, "-m", "mypy", "--config-file", str(REPO / "pyproject.toml")],
        cwd=REPO,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "Success: no issues found" in done.stdout
