"""Content digests of what an experiment stores: the seal that makes a change visible.

**What they protect against:** accidental edits, partial copies, a stale or mixed folder, a
careless hand edit of a table or a file, a removed trial or recording. **What not:** someone
who edits the data and recomputes the digests (SHA-256 in plain JSON, no key); against that,
the sealed root (``seal.json``) of a committed experiment is in git, so any change to it shows
in ``git status`` and in the history.

Layout (beside :mod:`lonlib.storage.layout`)::

    data/<experiment>/seal.json              the root: the configuration's digest, the
                                             sessions' result-path versions, each run's
                                             trial count and chain head, the recordings
                                             index, the figures and the inputs they were
                                             drawn from, the chains' configuration
    p=<p>/run_<run>/digests.json             the run's chain: per trial, the digest of its
                                             row of the trials table and of its files
                                             (optimum, history)
    data/<experiment>/manifest.json          ``"sealed": true`` once the folder is sealed

Each run's entries are chained (entry *i* hashes entry *i − 1*'s chain value) from a start
made of the run's name and the configuration's digest when the experiment was first sealed
(``chain_config``, kept in the root and in each run's ``digests.json``), and the root keeps
each run's count and head, so removing a run's last trials (rows, files and entries alike)
no longer matches the root, and a run moved in from an experiment of another configuration
is named. Folders sealed before ``chain_config`` existed keep their chains (started from the
run's name alone) until they are sealed again from scratch. The manifest records that the
folder was sealed, so a folder that lost its seal and every run's digests is tampered data,
not an unsealed one.

**Write order** (each file by atomic rename): a trial's history and optimum, the run's
``digests.json`` (the trial sealed ahead), the trials table (the run's commit point), and the
root at the session's open and close. A SIGKILL between two of them leaves a folder that reads
as *pending*, never as tampered: files of a trial the table lacks are leftovers the next run
overwrites; a trial sealed ahead of a table write that did not happen is redone by the next
process that takes the run (:func:`drop_unwritten_trials`); a run chain longer than the root's
count is recorded in the root at the next session. A row the run's digests do not seal, and
anything else that differs, is tampered data. ``lonlib analyse`` and ``lonlib record`` write
their outputs under temporary names, seal their digests ahead in the root
(:func:`seal_outputs_ahead`: ``figures.next``, ``recordings_next``), rename them into place and
reseal (:func:`reseal_outputs`; :mod:`lonlib.storage.outputs`): killed part-way, each output
is as sealed or as sealed ahead (pending), and the same command again completes it.

A folder that is not an experiment (a study's summaries) gets a ``files`` seal: each file's
digest (:func:`seal_files`, :func:`check_files_seal`).

This module is where the seal's names are imported from; its code lies in private modules by
job: what a seal holds and how it is read and written (``_digests_format``), its writers
(``_digests_write``), the checks of an experiment against it (``_digests_check``) and the
seal of a folder of files (``_digests_files``).
"""

from __future__ import annotations

from lonlib.storage._digests_check import (
    SealCheck,
    check_experiment_seal,
    check_readable,
)
from lonlib.storage._digests_files import (
    check_files_seal,
    reseal_files_if_sealed,
    seal_files,
)
from lonlib.storage._digests_format import (
    RUN_DIGESTS,
    SEAL_NAME,
    SEALED_FIELD,
    TamperedDataError,
    TamperedDataWarning,
    UnsealedDataWarning,
    bytes_digest,
    figure_files,
    file_digest,
    is_sealed,
    loaded_inputs,
    row_digests,
)
from lonlib.storage._digests_write import (
    append_trial,
    drop_unwritten_trials,
    mark_sealed,
    refresh_root,
    reseal_files,
    reseal_outputs,
    seal_ahead,
    seal_outputs_ahead,
    seal_runs,
    settle_ahead,
    stale_figures,
    write_root,
)

__all__ = [
    "RUN_DIGESTS",
    "SEALED_FIELD",
    "SEAL_NAME",
    "SealCheck",
    "TamperedDataError",
    "TamperedDataWarning",
    "UnsealedDataWarning",
    "append_trial",
    "bytes_digest",
    "check_experiment_seal",
    "check_files_seal",
    "check_readable",
    "drop_unwritten_trials",
    "figure_files",
    "file_digest",
    "is_sealed",
    "loaded_inputs",
    "mark_sealed",
    "refresh_root",
    "reseal_files",
    "reseal_files_if_sealed",
    "reseal_outputs",
    "row_digests",
    "seal_ahead",
    "seal_files",
    "seal_outputs_ahead",
    "seal_runs",
    "settle_ahead",
    "stale_figures",
    "write_root",
]
