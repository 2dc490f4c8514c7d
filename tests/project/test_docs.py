"""The README and the documentation site: the README fits a screen, the site builds offline
with ``--strict`` (broken links fail), the generated tables equal what the code generates
from the committed data, and every ``lonlib`` and ``make`` command the README and the docs
show is checked (a dry run, or for real where it is cheap and reads only)."""

from __future__ import annotations

import importlib
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
import torch
import yaml

import lonlib.ddpg
from lonlib.analysis.claims import peaks_beside_paper
from lonlib.analysis.claims_report import README_BEGIN as CLAIMS_BEGIN
from lonlib.analysis.claims_report import README_END as CLAIMS_END
from lonlib.analysis.claims_report import claims_markdown, splice_readme
from lonlib.analysis.claims_rescored import README_BEGIN as ROBUST_BEGIN
from lonlib.analysis.claims_rescored import side_by_side_markdown, splice_side_by_side
from lonlib.analysis.holding import README_BEGIN as HOLDING_BEGIN
from lonlib.analysis.holding import holding_markdown, holding_summary, splice_holding
from lonlib.analysis.reference_controllers import BEGIN as REFERENCE_CONTROLLERS_BEGIN
from lonlib.analysis.reference_controllers import END as REFERENCE_CONTROLLERS_END
from lonlib.analysis.summary import README_BEGIN as SUMMARY_BEGIN
from lonlib.analysis.summary import splice_summary, summary_markdown
from lonlib.calibration.report import DRIFT_HEADER, README_BEGIN, README_END
from lonlib.cli import build_parser, main
from lonlib.storage.trials import read_experiment_trials
from lonlib.util.readme_tables import has_markers, splice_generated

ROOT = Path(__file__).parents[2]
README = ROOT / "README.md"
PAGES = sorted((ROOT / "docs").rglob("*.md"))
REFERENCE = ROOT / "data" / "reference"
MKDOCS = Path(sys.executable).with_name("mkdocs")


def test_the_readme_fits_a_screen_and_its_first_screen_holds_the_essentials():
    lines = README.read_text().splitlines()
    assert len(lines) <= 250
    first = "\n".join(lines[:150])
    for needed in [
        "Local Optima Networks for Reinforcement Learning",  # the purpose: the paper
        "![3-D LON of the reference experiment",  # the reference LON figure
        "make reproduce   #",  # the two commands ...
        "make test        #",
        "```python",  # the Python example
        "## The result",
        "## Concepts and code",
        "lonlib.task",
        "@inproceedings{zhou2024lonrl",  # BibTeX
        "## Licence",
        "LICENSE",
        "data/reference/",
    ]:
        assert needed in first, needed
    # ... with their measured times
    assert re.search(r"`make setup` \d+ s,\s+`make test` \d+ s, `make reproduce` \d+ s", first)
    assert re.search(r"## Concepts and code\n(?:.*\n)*?\|---", first)  # a table


def sentences(text: str) -> int:
    """A simple sentence count: pieces ending in ``.``, ``!``, ``?``, ``:`` or ``;`` before
    a space or the end (a colon or semicolon starts a new sentence, for brevity's sake)."""
    return len([piece for piece in re.split(r"(?<=[.!?:;])\s+", text.strip()) if piece])


def test_the_readme_result_is_three_sentences_at_most():
    result = README.read_text().split("## The result\n")[1].split("\n## ")[0]
    assert sentences(result) <= 3, result
    assert sentences("A b: c. D e; f. G h 0.45, i. J") == 6
    assert (ROOT / "LICENSE").read_text().startswith("MIT License")
    assert "<!--" not in README.read_text()  # generated tables live in docs/, not here


def test_the_readme_python_example_runs(monkeypatch, capsys):
    block = re.search(r"```python\n(.*?)```", README.read_text(), re.S).group(1)
    monkeypatch.chdir(ROOT)
    exec(compile(block, "README.md", "exec"), {})
    printed = capsys.readouterr().out
    assert "[0.9405]" in printed and "funnels" in printed


@pytest.mark.skipif(not MKDOCS.exists(), reason="mkdocs is not installed (the docs extra)")
def test_the_site_builds_offline_and_strict(tmp_path):
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    build = subprocess.run(
        [str(MKDOCS), "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert build.returncode == 0, build.stderr[-3000:]
    site = tmp_path / "site"
    assert (site / "api" / "ddpg" / "index.html").read_text().count("doc-heading") > 10
    assert (site / "reference-figures" / "fig3_lon_p=0.0001.png").exists()
    # docstrings' Sphinx roles are code, and link to the API entry they name (docs_hooks.py)
    api = {page.parent.name: page.read_text() for page in (site / "api").glob("*/index.html")}
    assert not [name for name, html in api.items() if re.search(r":(class|func|meth):<", html)]
    assert 'href="../ddpg/#lonlib.ddpg.trainer.SlotTrainer"><code>' in api["calibration"]
    for page in site.rglob("*.html"):  # nothing is fetched from elsewhere when a page opens
        assert "fonts.googleapis" not in page.read_text(), page


def _block(text: str, begin: str, end: str) -> str:
    assert text.count(begin) == 1 and text.count(end) == 1, begin
    return text.split(begin)[1].split(end)[0]


@pytest.mark.parametrize(
    ("page_name", "source"),
    [("results.md", "data/reference"), ("one-cart.md", "data/one-cart")],
)
def test_the_generated_tables_equal_what_the_code_generates_from_the_committed_data(
    page_name, source
):
    page = (ROOT / "docs" / page_name).read_text()
    folder = ROOT / source
    figures = folder / "figures"
    summary = summary_markdown(pd.read_csv(figures / "summary.csv"))
    assert splice_summary(page, summary, source) == page
    claims = claims_markdown(
        pd.read_csv(figures / "claims.csv"),
        peaks_beside_paper(read_experiment_trials(folder)),
        pd.read_csv(figures / "power.csv"),
        pd.read_csv(figures / "claim_d_curve.csv"),
    )
    assert splice_readme(page, claims, source) == page
    assert splice_generated(page, CLAIMS_BEGIN, CLAIMS_END, claims, source) == page
    side = figures / "claims_nominal_robust.csv"
    robust = side_by_side_markdown(pd.read_csv(side)) if side.exists() else ""
    assert splice_side_by_side(page, robust, source) == page
    assert splice_side_by_side(page, "another table", source) != page  # the block is there
    # the stored summary is what the stored runs give (a commit of new searches without
    # `lonlib analyse` fails here)
    stored = read_experiment_trials(folder)
    table = pd.read_csv(figures / "summary.csv")
    assert int(table["local_searches"].sum()) == len(stored)
    if has_markers(page, HOLDING_BEGIN):  # and its holding table, one row per accepted optimum
        holding = pd.read_csv(figures / "holding.csv")
        assert splice_holding(page, holding_markdown(holding_summary(holding)), source) == page
        assert len(holding) == int(stored["accepted"].sum())


def test_a_page_names_its_own_command_in_the_begin_marker_and_keeps_it():
    from lonlib.util.readme_tables import splice

    begin = "<!-- summary:begin (lonlib analyse data/reference --docs docs/results.md) -->"
    own = "<!-- summary:begin (lonlib analyse data/one-cart --docs docs/one-cart.md) -->"
    page = f"head\n{own}\nold\n<!-- summary:end -->\ntail\n"
    pasted = splice(page, begin, "<!-- summary:end -->", "new table")
    assert pasted == f"head\n{own}\nnew table\n<!-- summary:end -->\ntail\n"
    with pytest.raises(ValueError, match="once each"):
        splice(page + own, begin, "<!-- summary:end -->", "x")
    with pytest.raises(ValueError, match="complete comment"):
        splice("<!-- summary:begin (x <!-- summary:end -->", begin, "<!-- summary:end -->", "x")


def test_every_generated_block_is_in_the_docs_once_and_the_drift_table_is_printed_once():
    text = {page: page.read_text() for page in PAGES}
    markers = [
        (SUMMARY_BEGIN, "<!-- summary:end -->"),
        (CLAIMS_BEGIN, CLAIMS_END),
        (ROBUST_BEGIN, "<!-- claims-robust:end -->"),
        (HOLDING_BEGIN, "<!-- holding:end -->"),
        (README_BEGIN, README_END),
        ("<!-- calibration-one-cart:begin -->", "<!-- calibration-one-cart:end -->"),
        ("<!-- calibration-batch2000:begin -->", "<!-- calibration-batch2000:end -->"),
        ("<!-- ddpg-speed:begin (python -m benchmarks.readme) -->", "<!-- ddpg-speed:end -->"),
        (
            "<!-- lockstep-speed:begin (python -m benchmarks.readme) -->",
            "<!-- lockstep-speed:end -->",
        ),
        (REFERENCE_CONTROLLERS_BEGIN, REFERENCE_CONTROLLERS_END),
    ]
    for begin, end in markers:
        holders = [page for page, body in text.items() if begin in body]
        assert len(holders) == 1, begin
        _block(text[holders[0]], begin, end)
    everything = "\n".join(text.values())
    assert everything.count(DRIFT_HEADER) == 1  # the integrator drift table, once


# --- every command the README and the docs show ---------------------------------------

# Inline spans that name a command's output or a pattern, not a command to run.
NOT_COMMANDS = {"lonlib verify: OK", "lonlib VERB --help"}
READERS = {"status", "lon", "analyse", "record", "verify", "thin"}
WRITERS = {"thin"}  # reading verbs that change the folder (without --dry-run)


def documented_commands() -> list[tuple[str, str]]:
    """(file, command) for every ``lonlib ...`` and ``make ...`` line of a ```bash block and
    every inline code span starting with one, in README.md and docs/."""
    found = []
    for path in [README, *PAGES]:
        text = path.read_text()
        name = str(path.relative_to(ROOT))
        for block in re.findall(r"```bash\n(.*?)```", text, re.S):
            for line in block.splitlines():
                line = line.split("#")[0].strip()
                if line.startswith(("lonlib ", "make ")):
                    found.append((name, line))
        for span in re.findall(r"`((?:lonlib|make) [^`]+)`", text):
            span = " ".join(span.split())
            if span not in NOT_COMMANDS:
                found.append((name, span))
    return sorted(set(found))


COMMANDS = documented_commands()


def test_the_docs_show_commands():
    assert len(COMMANDS) > 30
    assert (
        "docs/experiments.md",
        "lonlib run quick --scheduler dask-local --workers 2",
    ) in COMMANDS


@pytest.fixture
def project(tmp_path, monkeypatch):
    """A project folder for one command: the repository's data folders, configurations and
    notebooks linked in, the docs' own YAML example as ``my.yaml``, a grid ``best.yaml``."""
    (tmp_path / "data").mkdir()
    for folder in (ROOT / "data").iterdir():
        if folder.is_dir():
            (tmp_path / "data" / folder.name).symlink_to(folder)
    for name in ("configs", "notebooks", "docs"):
        (tmp_path / name).symlink_to(ROOT / name)
    example = re.search(r"```yaml\n(.*?)```", (ROOT / "docs/experiments.md").read_text(), re.S)
    (tmp_path / "my.yaml").write_text(example.group(1))
    (tmp_path / "best.yaml").write_text(
        yaml.safe_dump(
            {"base": "default", "name": "best", "cells": [{"motor": "velocity", "motor_tau": 0.02}]}
        )
    )
    monkeypatch.chdir(tmp_path)

    def parse_only(device: str) -> None:  # a documented GPU command, checked on a CPU machine
        torch.device(device)

    monkeypatch.setattr(lonlib.ddpg, "check_device", parse_only)
    return tmp_path


def _lonlib(argv: list[str], project: Path, capsys) -> str:
    """Check one documented ``lonlib`` command: cheap read-only ones for real, the others as
    a dry run. A folder a reading verb names and the repository lacks (``data/paper``) is
    stood in for by the reference experiment."""
    argv = [arg for arg in argv if arg not in "[]"]
    argv = [arg.strip("[]") for arg in argv]
    verb = argv[0]
    if verb in READERS and len(argv) > 1 and not Path(argv[1]).exists():
        Path(argv[1]).symlink_to(REFERENCE)
    if verb in WRITERS and len(argv) > 1:  # a dry run, but never on the committed data
        copy = project / "copy-of" / Path(argv[1]).name
        shutil.copytree(Path(argv[1]).resolve(), copy, ignore=shutil.ignore_patterns(".inflight"))
        argv[1] = str(copy)
    real = verb == "status"
    try:
        main(argv if real else [*argv, "--dry-run"])
    except SystemExit as stop:
        pytest.fail(f"lonlib {shlex.join(argv)} exited {stop.code}: {capsys.readouterr().err}")
    return capsys.readouterr().out


MAKE_TO_LONLIB = {"CONFIG": None, "WORKERS": "--workers", "SCHEDULER": "--scheduler"}


@pytest.mark.parametrize(("source", "command"), COMMANDS, ids=[c for _, c in COMMANDS])
def test_a_documented_command_works(source, command, project, capsys):
    words = shlex.split(command)
    if words[0] == "lonlib":
        verbs = build_parser()._actions[-1].choices
        if len(words) == 2 and words[1] in verbs:
            return  # a verb named in the text: it exists
        if words[1:] == ["--help"]:
            with pytest.raises(SystemExit) as stop:
                main(["--help"])
            assert stop.value.code == 0
            return
        out = _lonlib(words[1:], project, capsys)
        assert out, command
        return
    # make: the target exists and its recipe expands (make -n runs nothing) ...
    dry = subprocess.run(
        ["make", "-n", *words[1:]], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert dry.returncode == 0, f"{command}: {dry.stderr}"
    settings = dict(word.split("=", 1) for word in words[1:] if "=" in word)
    targets = [word for word in words[1:] if "=" not in word]
    rules = re.findall(r"^([\w-]+):", (ROOT / "Makefile").read_text(), re.M)
    assert set(targets) <= set(rules), command  # a rule of the Makefile, not a folder's name
    # ... and what it would sample or analyse is checked as the lonlib command it runs
    if "reproduce" in targets or not targets:
        config = settings.get("CONFIG", "quick")
        name = (
            yaml.safe_load(Path(config).read_text())["name"] if config.endswith(".yaml") else config
        )
        argv = ["run", config, "--workers", settings.get("WORKERS", "2")]
        argv += ["--out", settings.get("OUT", f"data/{name}")]
        for key, option in [
            ("SCHEDULER", "--scheduler"),
            ("EXECUTOR", "--executor"),
            ("SLOTS", "--slots"),
            ("DEVICE", "--device"),
        ]:
            if settings.get(key):
                argv += [option, settings[key]]
        assert "Nothing computed" in _lonlib(argv, project, capsys)
    if "figures" in targets:
        assert "would read" in _lonlib(
            ["analyse", settings.get("EXPERIMENT", "data/reference")], project, capsys
        )


# --- every dotted lonlib name and every Python example the README and the docs show ----

# A ```python block whose first line is this comment is not run by the tests (it trains for
# minutes); every other ```python block of README.md and docs/ is run.
NOT_RUN = "# not run in tests"
FENCE = re.compile(r"^```[^\n]*\n.*?^```", re.S | re.M)
SPAN = re.compile(r"`([^`\n]+(?:\n[^`\n]+)?)`")  # a code span, at most one line break inside
DOTTED = re.compile(r"\blonlib(?:\.[A-Za-z_]\w*)+")


def _code(text: str) -> list[str]:
    """The code blocks and code spans of a Markdown text (a span broken across a line joined)."""
    blocks = FENCE.findall(text)
    spans = [re.sub(r"\s*\n\s*", "", span) for span in SPAN.findall(FENCE.sub("", text))]
    return blocks + spans


def documented_names() -> list[tuple[str, str]]:
    found = set()
    for path in [README, *PAGES]:
        text = path.read_text()
        for code in [text, *_code(text)]:  # the prose too, and spans broken across lines
            for name in DOTTED.findall(code):
                found.add((str(path.relative_to(ROOT)), name))
    return sorted(found)


def resolves(name: str) -> bool:
    """Whether ``name`` is an importable module, or an attribute chain of the longest
    importable module prefix of it (a module of this tree under its own name, not an alias)."""
    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        try:
            found = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        if found.__name__ != ".".join(parts[:i]):
            return False
        for attribute in parts[i:]:
            if not hasattr(found, attribute):
                return False
            found = getattr(found, attribute)
        return True
    return False


# Imported as `make reproduce` runs it: papermill first, then its "lonlib" engine (either
# order works; tests/notebooks/test_notebook_run.py checks both).
importlib.import_module("papermill")
NAMES = documented_names()


def test_the_name_check_sees_the_docs_names_and_fails_on_an_old_path():
    assert len(NAMES) > 30
    assert ("docs/reproducing.md", "lonlib.storage.result_path.experiment_digest") in NAMES
    assert _code("a (`lonlib.result_path.\nexperiment_digest`) b") == [
        "lonlib.result_path.experiment_digest"
    ]
    assert not resolves("lonlib.basin_hopping")  # the old name, removed
    assert not resolves("lonlib.result_path.experiment_digest")
    assert not resolves("lonlib.storage.no_such_function")
    assert not resolves("lonlib.calibration.study.run_calibration")
    assert resolves("lonlib.calibration.campaign.run_calibration")


@pytest.mark.parametrize(("source", "name"), NAMES, ids=[f"{s}:{n}" for s, n in NAMES])
def test_a_documented_dotted_name_resolves(source, name):
    assert resolves(name), f"{source}: {name} is an old name, or neither a module nor an attribute"


# A file or folder of the package named in the docs (``lonlib/task/pendulum.py``); the
# environment id ``lonlib/CoupledPendulum-v1`` has capitals, so it is not one.
PACKAGE_PATH = re.compile(r"\blonlib/[a-z_][a-z0-9_/]*(?:\.py)?\b")


def documented_paths() -> list[tuple[str, str]]:
    found = set()
    for path in [README, *PAGES]:
        for name in PACKAGE_PATH.findall(path.read_text()):
            found.add((str(path.relative_to(ROOT)), name.rstrip("/")))
    return sorted(found)


PATHS = documented_paths()


def test_the_path_check_sees_the_docs_paths():
    assert ("docs/model.md", "lonlib/task/pendulum.py") in PATHS
    assert PACKAGE_PATH.findall("`lonlib/result_path.py` and lonlib/CoupledPendulum-v1") == [
        "lonlib/result_path.py"
    ]


@pytest.mark.parametrize(("source", "path"), PATHS, ids=[f"{s}:{p}" for s, p in PATHS])
def test_a_documented_package_path_exists(source, path):
    assert (ROOT / path).exists(), f"{source}: {path} is not a file or folder of the tree"


def test_the_docs_name_the_current_environment_id():
    for path in [README, *PAGES]:
        assert "CoupledPendulum-v0" not in path.read_text(), path


def python_examples() -> list[tuple[str, int, str]]:
    found = []
    for path in [README, *PAGES]:
        for i, block in enumerate(re.findall(r"```python\n(.*?)```", path.read_text(), re.S)):
            found.append((str(path.relative_to(ROOT)), i, block))
    return found


EXAMPLES = python_examples()


@pytest.mark.parametrize(
    ("source", "index", "block"), EXAMPLES, ids=[f"{s}#{i}" for s, i, _ in EXAMPLES]
)
def test_a_documented_python_example_runs(source, index, block, monkeypatch):
    if block.startswith(NOT_RUN):
        pytest.skip(f"{source}: marked {NOT_RUN!r}")
    import matplotlib

    matplotlib.use("Agg")
    monkeypatch.chdir(ROOT)
    exec(compile(block, f"{source}#{index}", "exec"), {})


def test_the_python_examples_are_found_and_only_long_ones_are_skipped():
    sources = {source for source, _, _ in EXAMPLES}
    assert {"README.md", "docs/rollout.md", "docs/ddpg.md"} <= sources
    skipped = [source for source, _, block in EXAMPLES if block.startswith(NOT_RUN)]
    assert skipped == ["docs/ddpg.md"]  # DDPG trains for minutes


def test_the_fitness_scale_table_is_what_the_committed_data_give():
    from lonlib.analysis.fitness_scale import BEGIN, END, fitness_scale_markdown
    from lonlib.util.readme_tables import splice

    page = (ROOT / "docs" / "results.md").read_text()
    assert splice(page, BEGIN, END, fitness_scale_markdown(ROOT)) == page
    assert splice(page, BEGIN, END, "another table") != page


def test_the_reference_controllers_table_is_what_the_controllers_score(tmp_path):
    from lonlib.analysis.reference_controllers import main, reference_controllers_markdown
    from lonlib.util.readme_tables import splice

    page = (ROOT / "docs" / "rollout.md").read_text()
    table = reference_controllers_markdown()
    assert splice(page, REFERENCE_CONTROLLERS_BEGIN, REFERENCE_CONTROLLERS_END, table) == page
    assert "| 0.9415: every rod up at step 92" in table  # README's example: 0.9405 on two
    (tmp_path / "docs").mkdir()  # the command writes the block into a project's page
    (tmp_path / "docs" / "rollout.md").write_text(
        f"head\n{REFERENCE_CONTROLLERS_BEGIN}\nold\n{REFERENCE_CONTROLLERS_END}\ntail\n"
    )
    assert main([str(tmp_path)]) == 0
    written = (tmp_path / "docs" / "rollout.md").read_text()
    assert table in written and written.startswith("head\n") and written.endswith("tail\n")
