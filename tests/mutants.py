"""Hand-written mutation testing: every mutant below changes a result-changing line of the
DDPG local search, Algorithm 2 or the physics, and ``make test`` must kill it.

``make mutants`` copies the package, the tests and the committed data (git's files under
``data/``, which some guard tests read) into temporary folders and applies one mutant at a
time to a copy (the working tree is never touched; ``--jobs N`` runs N copies at once), runs
the test files that guard that module, and reports each mutant as killed or SURVIVED; it
exits non-zero if any survived or if a mutant's text no longer occurs exactly once (keep the
list in step with the code). First it runs each set of guard tests on the unmutated copy
(``--no-baseline`` skips this): a guard that fails there would count every mutant as
killed. Add a mutant whenever you add a line whose change would alter results.
"""

from __future__ import annotations

import os
import queue
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Mutant:
    """Replace ``old`` (which must occur exactly once) by ``new`` in ``path``."""

    path: str
    old: str
    new: str
    why: str


DDPG, BH, SIM = "lonlib/ddpg/trainer.py", "lonlib/search/algorithm.py", "lonlib/task/pendulum.py"
SLOTS, TRAINER_CHECKPOINT = "lonlib/ddpg/slots.py", "lonlib/ddpg/checkpoint.py"
LEAN, AUTOGRAD = "lonlib/ddpg/lean.py", "lonlib/ddpg/reference.py"
REPLAY, STREAMS, LOCKSTEP = (
    "lonlib/ddpg/replay.py",
    "lonlib/ddpg/streams.py",
    "lonlib/experiment/lockstep.py",
)
ROLLOUT, NETS, PMATH = (
    "lonlib/task/rollout.py",
    "lonlib/task/policy.py",
    "lonlib/util/portable_math.py",
)
BEHAVIOUR, VERIFY = "lonlib/task/behaviour.py", "lonlib/analysis/_verify_replay.py"
CONFIGS, CHECKPOINTS = "lonlib/config/ddpg.py", "lonlib/experiment/checkpoints.py"
DEVICES = "lonlib/ddpg/devices.py"
KERNELS = "lonlib/task/kernels.py"
GYM_DDPG = "lonlib/ddpg/gymnasium_search.py"
GYM_BEHAVIOUR = "lonlib/task/gymnasium_behaviour.py"
GYM_DESCRIPTORS = "lonlib/task/gymnasium_descriptors.py"
RUNS = "lonlib/experiment/runs.py"
CLI_RUN, IMPORTS = "lonlib/cli/_experiments.py", "lonlib/util/imports.py"
DIGESTS_FORMAT, DIGESTS_WRITE = (
    "lonlib/storage/_digests_format.py",
    "lonlib/storage/_digests_write.py",
)
DIGESTS_CHECK, TRIALS = "lonlib/storage/_digests_check.py", "lonlib/storage/trials.py"
OUTPUTS, PIPELINE = "lonlib/storage/outputs.py", "lonlib/analysis/pipeline.py"
SESSION = "lonlib/storage/session.py"
JUDGED_LOG = "lonlib/calibration/judged_log.py"
HOLDING, POWER = "lonlib/analysis/holding.py", "lonlib/analysis/claims_power.py"
ONE_ROLLOUT = [
    "tests/task/test_rollout.py",
    "tests/storage/test_result_path.py",
    "tests/analysis/test_verify.py",
]
GUARDS = {
    DDPG: [
        "tests/ddpg/test_ddpg.py",
        "tests/ddpg/test_devices.py",
        "tests/experiment/test_lockstep.py",
        "tests/calibration/test_study.py",
    ],
    SLOTS: [
        "tests/ddpg/test_ddpg.py",
        "tests/ddpg/test_devices.py",
        "tests/experiment/test_lockstep.py",
        "tests/calibration/test_study.py",
    ],
    TRAINER_CHECKPOINT: [
        "tests/ddpg/test_ddpg.py",
        "tests/ddpg/test_devices.py",
        "tests/experiment/test_lockstep.py",
        "tests/calibration/test_study.py",
        "tests/experiment/test_inflight.py",
    ],
    REPLAY: [
        "tests/ddpg/test_devices.py",
        "tests/ddpg/test_ddpg.py",
        "tests/experiment/test_lockstep.py",
    ],
    STREAMS: [
        "tests/ddpg/test_random_streams.py",
        "tests/ddpg/test_devices.py",
        "tests/ddpg/test_ddpg.py",
        "tests/experiment/test_lockstep.py",
    ],
    DEVICES: [
        "tests/ddpg/test_devices.py",
        "tests/ddpg/test_random_streams.py",
        "tests/experiment/test_lockstep.py",
    ],
    LOCKSTEP: ["tests/experiment/test_lockstep.py", "tests/experiment/test_drain.py"],
    CHECKPOINTS: ["tests/experiment/test_lockstep.py", "tests/experiment/test_inflight.py"],
    CONFIGS: [
        "tests/ddpg/test_ddpg.py",
        "tests/experiment/test_lockstep.py",
        "tests/calibration/test_study.py",
    ],
    LEAN: [
        "tests/ddpg/test_ddpg.py",
        "tests/ddpg/test_ddpg_update.py",
        "tests/ddpg/test_devices.py",
        "tests/experiment/test_lockstep.py",
    ],
    AUTOGRAD: ["tests/ddpg/test_ddpg.py", "tests/ddpg/test_ddpg_update.py"],
    BH: ["tests/search/test_basin_hopping.py"],
    # the numpy definition is the kernels' oracle: only test_compiled_rollout runs it
    SIM: [
        "tests/task/test_pendulum.py",
        "tests/task/test_rollout.py",
        "tests/task/test_compiled_rollout.py",
    ],
    ROLLOUT: [*ONE_ROLLOUT, "tests/calibration/test_study.py"],
    NETS: ["tests/ddpg/test_nets.py", *ONE_ROLLOUT, "tests/task/test_compiled_rollout.py"],
    PMATH: [*ONE_ROLLOUT, "tests/task/test_compiled_rollout.py"],
    BEHAVIOUR: [
        "tests/task/test_behaviour.py",
        *ONE_ROLLOUT,
        "tests/calibration/test_calibration.py",
    ],
    VERIFY: [
        "tests/analysis/test_verify.py",
        "tests/experiment/test_gymnasium_runs.py",
        "tests/analysis/test_verify_task.py",
    ],
    JUDGED_LOG: ["tests/calibration/test_study.py"],
    HOLDING: ["tests/analysis/test_holding.py", "tests/analysis/test_verify.py"],
    POWER: ["tests/analysis/test_claims_power.py"],
    KERNELS: ["tests/task/test_compiled_rollout.py"],
    # the outputs of analyse and record sealed ahead: test_outputs kills them at each point
    DIGESTS_FORMAT: ["tests/storage/test_digests.py", "tests/storage/test_outputs.py"],
    DIGESTS_WRITE: ["tests/storage/test_digests.py", "tests/storage/test_outputs.py"],
    DIGESTS_CHECK: ["tests/storage/test_digests.py", "tests/storage/test_outputs.py"],
    OUTPUTS: ["tests/storage/test_outputs.py"],
    PIPELINE: ["tests/storage/test_outputs.py"],
    GYM_DDPG: ["tests/ddpg/test_gymnasium_search.py"],
    GYM_BEHAVIOUR: [
        "tests/task/test_gymnasium_behaviour.py",
        "tests/experiment/test_gymnasium_runs.py",
    ],
    GYM_DESCRIPTORS: ["tests/task/test_gymnasium_descriptors.py"],
    RUNS: ["tests/experiment/test_gymnasium_runs.py"],
    CLI_RUN: ["tests/cli/test_cli.py"],
    IMPORTS: ["tests/task/test_gymnasium_behaviour.py"],
    TRIALS: ["tests/storage/test_digests.py"],
    SESSION: ["tests/storage/test_digests.py"],
}

MUTANTS = [
    # --- digests: each line below is what makes one kind of change visible
    Mutant(
        DIGESTS_CHECK,
        'if len(entries) < count or entries[count - 1]["chain"] != run.sealed["head"]:',
        "if len(entries) < count:",
        "the root's chain head is not compared (a run rewritten to its count passes)",
    ),
    Mutant(
        DIGESTS_CHECK,
        "    if len(rows) > len(entries):",
        "    if False:",
        "a row appended by hand is not named",
    ),
    Mutant(
        DIGESTS_CHECK,
        "if len(rows) < count:",
        "if False:",
        "a run's last rows and files removed under kept digests read as sealed ahead (resume "
        "re-samples them)",
    ),
    Mutant(
        DIGESTS_CHECK,
        'check.problems.append((f"{run.key}/{name}", "a sealed file is missing"))',
        "pass",
        "a deleted history or optimum is not named (histories are not replayed)",
    ),
    Mutant(
        DIGESTS_CHECK,
        'check.problems.append((f"{run.key}/{path.name}", "a file no seal lists"))',
        "pass",
        "an extra file no seal lists in a run's folder is not named",
    ),
    Mutant(
        DIGESTS_CHECK,
        "elif file_digest(path) not in accepted:",
        "elif False:",
        "a changed optimum or history passes",
    ),
    Mutant(
        DIGESTS_CHECK,
        'if config_digest(manifest) not in (seal.get("config"), seal.get("config_next")):',
        "if False:",
        "an edited setting passes",
    ),
    Mutant(
        DIGESTS_CHECK,
        'if file_digest(folder / name) != listed[name].get("sha256"):',
        "if False:",
        "a changed recording passes",
    ),
    Mutant(
        TRIALS,
        'fitness = float(table["fitness"].iloc[state.incumbent_index])',
        "fitness = float(stored.fitness)",
        "the incumbent on resume takes the optimum file's copy of f*",
    ),
    Mutant(
        DIGESTS_WRITE,
        'seal["config_next"] = config_digest(next_manifest)',
        "pass",
        "a changed setting is not sealed ahead of its manifest (config_next)",
    ),
    Mutant(
        SESSION,
        "write_root(out, stored, next_manifest=manifest)",
        "pass",
        "a session does not seal the root ahead of its manifest",
    ),
    Mutant(
        DIGESTS_CHECK,
        "    elif manifest.get(SEALED_FIELD) is True:",
        "    elif False:",
        "a folder that lost its seal and every digest reads as unsealed",
    ),
    Mutant(
        SESSION,
        "manifest[SEALED_FIELD] = True",
        "pass",
        "a new experiment's manifest does not record its seal",
    ),
    Mutant(
        DIGESTS_WRITE,
        "    write_root(root, manifest)\n    mark_sealed(root)",
        "    write_root(root, manifest)",
        "verify --seal does not record the seal in the manifest",
    ),
    Mutant(
        DIGESTS_CHECK,
        "if run.chains is not None and config != run.chains:",
        "if False:",
        "a run chained from another configuration passes",
    ),
    Mutant(
        DIGESTS_FORMAT,
        'return bytes_digest(f"lonlib run {key} config {config}".encode())',
        'return bytes_digest(f"lonlib run {key}".encode())',
        "a run's chain starts from its name alone, not its configuration",
    ),
    Mutant(
        DIGESTS_WRITE,
        'seal["chain_config"] = chains',
        "pass",
        "the root forgets the chains' configuration",
    ),
    Mutant(
        DIGESTS_CHECK,
        "        elif file_digest(path) != digest:\n"
        "            check.problems.append(\n"
        '                (name, "differs from its seal (a figure: `lonlib analyse` '
        'regenerates it)")\n'
        "            )",
        "        elif False:\n            pass",
        "a changed figure passes",
    ),
    Mutant(
        DIGESTS_CHECK,
        "        if not path.is_file():\n            check.problems.append(\n"
        '                (name, "a sealed figure',
        "        if False:\n            check.problems.append(\n"
        '                (name, "a sealed figure',
        "a missing figure passes",
    ),
    Mutant(
        DIGESTS_CHECK,
        "        if name not in listed:",
        "        if False:",
        "a figure the seal does not list passes",
    ),
    Mutant(
        DIGESTS_CHECK,
        "stale = [name for name in sorted(drawn) if drawn[name] != now]",
        "stale: list[str] = []",
        "stale figures are not reported",
    ),
    Mutant(
        DIGESTS_WRITE,
        "if name not in files and (root / name).is_file():",
        "if False:",
        "an analysis without the conditioning drops the earlier figures from the seal",
    ),
    Mutant(
        DIGESTS_WRITE,
        "            if recorded != inputs:\n                drawn[name] = recorded",
        "            pass",
        "figures kept from an earlier analysis are sealed as drawn from the current trials",
    ),
    Mutant(
        DIGESTS_WRITE,
        "if drawn is None or drawn != now:",
        "if False:",
        "verify --seal seals stale figures as drawn from the current trials",
    ),
    Mutant(
        DIGESTS_CHECK,
        "        if name in ahead:\n            continue  # as sealed ahead (or removed so)",
        "        if False:\n            continue",
        "a figure put in place as sealed ahead (an analysis killed part-way) reads as tampered",
    ),
    Mutant(
        DIGESTS_CHECK,
        'if file_digest(folder / name) == (ahead or {})[name].get("sha256")',
        "if False",
        "a recording put in place as sealed ahead (a record killed part-way) reads as tampered",
    ),
    Mutant(
        DIGESTS_WRITE,
        "            files[name], drawn[name] = digest, inputs",
        "            pass",
        "the seal forgets a figure a killed analysis put in place and the next did not write",
    ),
    Mutant(
        OUTPUTS,
        "    seal_outputs_ahead(root, figures=ahead, inputs=inputs)",
        "    pass",
        "analyse renames its figures into place without sealing them ahead",
    ),
    Mutant(
        OUTPUTS,
        "    seal_outputs_ahead(root, figures=ahead, inputs=inputs)",
        "    seal_outputs_ahead(root, figures=ahead)",
        "analyse seals its figures ahead as drawn from the trials sealed now, not those loaded",
    ),
    Mutant(
        DIGESTS_FORMAT,
        '"head": entries[count - 1]["chain"],',
        '"head": entries[-1]["chain"],',
        "the loaded inputs name a run's newest chain head, not the head at the count read",
    ),
    Mutant(
        OUTPUTS,
        "    seal_outputs_ahead(root, recordings=ahead)",
        "    pass",
        "record renames its recordings into place without sealing them ahead",
    ),
    Mutant(
        OUTPUTS,
        "    ahead.update({_key(root, folder / name): None for name in gone})",
        "    pass",
        "a figure an analysis removes is removed without its removal sealed ahead",
    ),
    Mutant(
        DIGESTS_FORMAT,
        "elif digest is not None and path.is_file() and file_digest(path) == digest:",
        "elif digest is not None and path.is_file():",
        "a figure sealed ahead is accepted whatever it holds (tampered while pending passes)",
    ),
    Mutant(
        DIGESTS_CHECK,
        'if file_digest(folder / name) == (ahead or {})[name].get("sha256")',
        "if True",
        "a recording sealed ahead is accepted whatever it holds (tampered while pending passes)",
    ),
    Mutant(
        PIPELINE,
        "index = {**recordings_index(folder), **recordings_index(folder, files=set(paths))}",
        "index = recordings_index(folder, files=set(paths))",
        "record's index lists only the recordings it wrote (a smaller record drops the others)",
    ),
    Mutant(
        DIGESTS_WRITE,
        '    elif recordings is None and "recordings_next" in old:\n'
        '        seal["recordings_next"] = old["recordings_next"]',
        "    elif False:\n        pass",
        "a later reseal (analyse, thin) forgets the recordings a killed record sealed ahead",
    ),
    Mutant(
        OUTPUTS,
        "with exclusive_lock(folder / OUTPUTS_LOCK, record_holder=False):",
        "with open(os.devnull):",
        "two analyses (or records) of one folder stage and publish at once (no outputs lock)",
    ),
    Mutant(
        PIPELINE,
        "removed.extend(ROBUST_CLAIMS_FILES)",
        "pass",
        "the robust claims an analysis no longer makes stay (stale) in the figures",
    ),
    Mutant(
        DIGESTS_CHECK,
        "if outputs.problems and check.ok:",
        "if False:",
        "a check that read the seal before an analysis renamed its outputs reports them as "
        "differing (no second read)",
    ),
    Mutant(
        DIGESTS_FORMAT,
        "bad = [n for n in keys if not _is_figure_key(n)]",
        "bad = []",
        "figures.next may name a file outside figures/",
    ),
    Mutant(
        DIGESTS_FORMAT,
        '        ("figures.files", figures.get("files", {})),\n',
        "",
        "a settled figure (figures.files) may name a file outside figures/",
    ),
    Mutant(
        DIGESTS_FORMAT,
        '        ("figures.inputs_of", drawn),\n',
        "",
        "figures.inputs_of may name a file outside figures/",
    ),
    Mutant(
        DIGESTS_FORMAT,
        "bad = [n for n in recordings if not _is_file_name(n)]",
        "bad = []",
        "recordings_next may name a file outside recordings/",
    ),
    Mutant(
        DIGESTS_FORMAT,
        "bad = [n for n in recordings if not _is_file_name(n)]",
        'bad = [n for n in recordings if name == "recordings_next" and not _is_file_name(n)]',
        "a settled recording may name a file outside recordings/",
    ),
    Mutant(
        DIGESTS_FORMAT,
        '        and len(name.encode("utf-8", "surrogatepass")) <= MAX_NAME_BYTES\n',
        "",
        "a sealed file name may be longer than 255 bytes",
    ),
    Mutant(
        DIGESTS_FORMAT,
        'len(name.encode("utf-8", "surrogatepass")) <= MAX_NAME_BYTES',
        "len(name) <= MAX_NAME_BYTES",
        "a sealed file name's bound counts characters, not UTF-8 bytes",
    ),
    Mutant(
        DIGESTS_FORMAT,
        "or len(name) > MAX_KEY_CHARS:",
        "or False:",
        "a sealed figure key may be longer than 4096 characters",
    ),
    Mutant(
        OUTPUTS,
        "        if planted:\n            staging.unlink()",
        "        if planted:\n            pass",
        "a file or link planted under the staging name blocks analyse and record",
    ),
    Mutant(
        DIGESTS_WRITE,
        "        remove_temporary_files(root, SEAL_NAME)",
        "        pass",
        "what a killed write of the root left stays",
    ),
    Mutant(
        OUTPUTS,
        "folder = _target(staged, staging)",
        "folder = _target(staged)",
        "an analysis that writes nothing does not remove the files it no longer makes",
    ),
    Mutant(
        DIGESTS_WRITE,
        "drawn = figures_inputs or inputs_digest(seal)",
        "drawn = inputs_digest(seal)",
        "figures are sealed as drawn from the trials at the seal, not those the analysis loaded",
    ),
    # --- judging: how often, and what a judged policy is described from
    Mutant(DDPG, "candidate &= crossed", "candidate = candidate", "judge_every is ignored"),
    Mutant(
        DDPG,
        "crossed = self.steps[slots] // every > previous_end // every",
        "crossed = self.steps[slots] // every >= previous_end // every",
        "judge_every judges episodes that cross no multiple",
    ),
    Mutant(
        ROLLOUT,
        "head = Rollout(*(getattr(result, name)[:rows] for name in _ROLLOUT_ARRAYS), result.trace)",
        "head = Rollout(*(getattr(result, name)[:rows] for name in _ROLLOUT_ARRAYS))",
        "the robust estimate's judged episodes lose their trace",
    ),
    Mutant(
        ROLLOUT,
        "trace=rows if trace else False",
        "trace=1 if trace else False",
        "the robust estimate traces only the first judged episode",
    ),
    Mutant(
        JUDGED_LOG,
        'rows["fitness_mean"].append(d.fitness_mean)',
        'rows["fitness_mean"].append(d.fitness_all)',
        "the judged log's mean aggregation is the all one",
    ),
    Mutant(
        DDPG,
        "candidate &= crossed",
        "candidate = trained & crossed",
        "count_start's warm-up policies are never judged with judge_every",
    ),
    Mutant(
        TRAINER_CHECKPOINT,
        'ddpg = {**ddpg, "judge_every": 0}',
        "ddpg = ddpg",
        "checkpoints written before judge_every cannot be read",
    ),
    Mutant(
        CONFIGS,
        "if hp.judge_every >= hp.patience_steps and hp.min_steps < hp.max_steps:",
        "if False:",
        "judge_every may outlast the patience",
    ),
    Mutant(
        JUDGED_LOG,
        "d = describe_rollout(nominal, self.env, row)",
        "d = describe_rollout(nominal, self.env, 0)",
        "judged policies described from the batch's first episode",
    ),
    Mutant(
        CONFIGS,
        'if ddpg.get("judge_every") == 0:',
        'if "judge_every" in ddpg:',
        "judge_every is not a stored setting",
    ),
    # --- DDPG: the lean update (the default learner)
    Mutant(
        LEAN,
        "torch.mul(row, -1.0 / size, out=self._row)",
        "torch.mul(row, 1.0 / size, out=self._row)",
        "actor descends Q",
    ),
    Mutant(
        LEAN,
        "self.actor_params[0].lerp_(self.actor_params[1], self.tau)",
        "self.actor_params[0].lerp_(self.actor_params[1], 0.0)",
        "no soft target update of the Actor",
    ),
    Mutant(
        LEAN,
        "self.critic_params[1].lerp_(self.critic_params[0], self.tau)",
        "self.critic_params[1].lerp_(self.critic_params[0], 1.0 - self.tau)",
        "tau and 1 - tau swapped in the Critic's target",
    ),
    Mutant(
        LEAN,
        "torch.addcmul(rewards, not_done, self._q_next, value=self.gamma, out=self._target)",
        "torch.addcmul(rewards, torch.ones_like(not_done), self._q_next, value=self.gamma,"
        " out=self._target)",
        "bootstraps past a termination",
    ),
    Mutant(
        LEAN,
        "torch.addcmul(rewards, not_done, self._q_next, value=self.gamma, out=self._target)",
        "torch.addcmul(rewards, not_done, self._q_next, value=1.0, out=self._target)",
        "gamma ignored",
    ),
    Mutant(LEAN, "dq.mul_(2.0 / size)", "dq.mul_(1.0 / size)", "critic gradient halved"),
    Mutant(
        LEAN,
        "exp_avg_sq.mul_(beta2).addcmul_(grad, grad, value=1.0 - beta2)",
        "exp_avg_sq.mul_(beta2).addcmul_(grad, grad, value=1.0)",
        "Adam's second moment",
    ),
    # --- DDPG: the autograd reference update (update="autograd")
    Mutant(AUTOGRAD, "actor_loss = -critic(", "actor_loss = critic(", "autograd: actor descends Q"),
    Mutant(
        AUTOGRAD,
        "torch._foreach_lerp_(target_net.tensors, net.tensors, tau)",
        "torch._foreach_lerp_(target_net.tensors, net.tensors, 0.0)",
        "autograd: no soft target update",
    ),
    Mutant(
        AUTOGRAD,
        "target = rewards + gamma * not_done * next_q",
        "target = rewards + gamma * next_q",
        "autograd: bootstraps past a termination",
    ),
    Mutant(
        AUTOGRAD,
        "critic_loss = ((q - target) ** 2).mean(dim=(1, 2))",
        "critic_loss = (q - target).abs().mean(dim=(1, 2))",
        "autograd: critic loss is not the squared error",
    ),
    # --- DDPG: replay, exploration and the per-agent streams
    Mutant(
        REPLAY,
        "self.add(obs, actions, outcome.reward, next_obs, outcome.terminated)",
        "self.add(obs, actions, outcome.reward, next_obs, outcome.terminated | outcome.truncated)",
        "truncations stored as terminations",
    ),
    Mutant(
        REPLAY, "outcome[:, -1] = ~terminated", "outcome[:, -1] = terminated", "not_done inverted"
    ),
    Mutant(
        DDPG,
        "self.replay.add_step(self._obs, actions, outcome, next_obs)",
        "self.replay.add_step(self._obs, actions, outcome, self.obs)",
        "next state not stored",
    ),
    Mutant(
        REPLAY,
        "self.position[agent] = self.size[agent] = 0",
        "self.position[agent] = 0",
        "a refilled slot samples the previous search's transitions",
    ),
    Mutant(
        DDPG,
        "return torch.clamp(mu.to(torch.float64) + noise_std * noise, 0.0, 1.0)",
        "return torch.clamp(mu.to(torch.float64) + noise_std**2 * noise, 0.0, 1.0)",
        "noise_std read as a variance",
    ),
    Mutant(
        DDPG,
        "return torch.clamp(mu.to(torch.float64) + noise_std * noise, 0.0, 1.0)",
        "return mu.to(torch.float64) + noise_std * noise",
        "actions not clipped",
    ),
    Mutant(
        DDPG,
        "REPLAY_SAMPLES, self._device_steps, hp.batch_size, self.replay.size",
        "REPLAY_SAMPLES, self._device_steps + torch.arange(self.slots), hp.batch_size,"
        " self.replay.size",
        "replay samples depend on the slot (K-dependent)",
    ),
    Mutant(
        STREAMS,
        "            self.seeds[agent] = seed\n",
        "            self.seeds[agent] = seed + agent\n",
        "a slot's stream depends on the slot",
    ),
    # --- DDPG: lockstep slots
    Mutant(
        DDPG,
        "for slot in np.flatnonzero(training & (self.updates == 0) & self.dirty):",
        "for slot in np.flatnonzero(training & (self.updates == 0) & ~self.dirty):",
        "a slot touched during its warm-up is not restored to its start",
    ),
    Mutant(
        DDPG,
        "            self.dirty |= ~training\n",
        "",
        "updates during the warm-up are kept",
    ),
    Mutant(
        DDPG,
        "self.learner = self.learner.select(keep)",
        "self.learner = self.learner.select(keep[::-1])",
        "shrinking mixes up the slots' learners",
    ),
    Mutant(
        LOCKSTEP,
        "trainer.free_slots()[: len(runs)],",
        "trainer.free_slots()[:1] * len(runs),",
        "two refills land in one slot",
    ),
    Mutant(
        DDPG,
        "self.pending = [item for item in self.pending if id(item[0]) in kept]",
        "self.pending = list(self.pending)",
        "a split batch judges the other part's queued policies",
    ),
    Mutant(
        LOCKSTEP,
        "if slot is None or run.driver.finished or len(run.driver.state.trials) != trials:",
        "if slot is None or run.driver.finished:",
        "a slot older than its run's stored trials is resumed",
    ),
    Mutant(
        LOCKSTEP,
        "np.array_equal(search.theta, run.request.theta)",
        "True or np.array_equal(search.theta, run.request.theta)",
        "a slot holding another start than its run asks for is resumed",
    ),
    # --- draining (--drain-after): what a drained call stores
    Mutant(
        LOCKSTEP,
        "if run.driver.finished or drained:",
        "if run.driver.finished:",
        "a draining batch refills its slots (drain ignored)",
    ),
    Mutant(
        LOCKSTEP,
        "run = None if drained else self.open_next()",
        "run = self.open_next()",
        "a draining batch starts the next pending run",
    ),
    Mutant(
        CHECKPOINTS,
        'for prefix, ours, theirs in (("", hp, hp_theirs), ("env.", env_config, env_theirs)):',
        'for prefix, ours, theirs in (("env.", env_config, env_theirs),):',
        "a batch trained with other DDPG settings (threads, device) is resumed",
    ),
    # --- DDPG on a device: state kept there, copies through lonlib.ddpg.devices, and the
    # branches a CUDA device takes (reached on the CPU by the tests' cpu_as_device)
    Mutant(
        LEAN,
        "torch.clamp(self.adam_steps, max=ADAM_TABLE_STEPS, out=self._table_rows)",
        "torch.clamp(self.adam_steps - 1, min=1, max=ADAM_TABLE_STEPS, out=self._table_rows)",
        "device: Adam's bias corrections a step behind",
    ),
    Mutant(
        LEAN,
        "self.adam_steps.copy_(to_device(steps, self.device, torch.int64))",
        "pass",
        "device: a restored batch restarts its Adam step counts",
    ),
    Mutant(
        LEAN,
        "        self.adam_steps[agent] = 0\n",
        "",
        "device: a refilled slot goes on with the previous search's Adam step count",
    ),
    Mutant(
        LEAN,
        "out.adam_steps.copy_(self.adam_steps[rows])",
        "pass",
        "device: a shed batch restarts its Adam step counts",
    ),
    Mutant(
        REPLAY,
        "self.position.add_(1).remainder_(self.capacity)",
        "self.position.add_(1).clamp_(max=self.capacity - 1)",
        "device: the replay ring does not wrap",
    ),
    Mutant(
        REPLAY,
        "self.size.add_(1).clamp_(max=self.capacity)",
        "self.size.add_(1)",
        "device: a slot's fill level passes its capacity",
    ),
    Mutant(
        DDPG,
        "        self._device_steps += self._device_busy\n",
        "",
        "device: the device's step counters stand still",
    ),
    Mutant(
        DDPG,
        "self.loss_sum[:, to_device(index, self.device)] = 0.0\n        self._counters_changed()",
        "self.loss_sum[:, to_device(index, self.device)] = 0.0",
        "device: a refilled slot's counters on the device are the previous search's",
    ),
    Mutant(
        DDPG,
        "            self._obs.copy_(device_next_obs)",
        "            pass",
        "device: the Actor acts on the device's stale observations",
    ),
    Mutant(
        DDPG,
        "        copy_to_device(self.obs, self._obs)\n\n    def _end_episodes",
        "\n    def _end_episodes",
        "device: reset observations never reach the device",
    ),
    Mutant(
        DDPG,
        "mask = self._device_busy & (self._device_steps >= hp.warmup_steps)",
        "mask = self._device_busy & (self._device_steps > hp.warmup_steps)",
        "device: the loss sums miss a search's first update",
    ),
    Mutant(
        DDPG,
        "actions = torch.where((steps < warmup)[:, None], actions, explore)",
        "actions = torch.where((steps <= warmup)[:, None], actions, explore)",
        "device: one more uniform warm-up action",
    ),
    Mutant(
        STREAMS,
        "return (x >> bits) & ((1 << (64 - bits)) - 1)",
        "return x >> bits",
        "device: the torch hash shifts arithmetically",
    ),
    Mutant(
        STREAMS,
        "self._words = _HOST_WORDS if is_host(self.device) else _TorchWords(self.device)",
        "self._words = _HOST_WORDS",
        "device: a device's streams hash on the host",
    ),
    Mutant(
        DEVICES,
        'return torch.device(device).type == "cpu" and not _CPU_AS_DEVICE',
        'return torch.device(device).type == "cpu"',
        "device: the tests' switch leaves the CPU the host",
    ),
    Mutant(
        DEVICES,
        'return tensor.detach().to("cpu", copy=True).numpy()',
        "return tensor.detach().cpu().numpy()",
        "device: to_host shares the CPU's memory",
    ),
    Mutant(
        STREAMS,
        "values.dtype != torch.int64 or not on_device(values, self.device)",
        "not on_device(values, self.device)",
        "device: the streams hash int32 counters",
    ),
    # tensors on the wrong device, waits and copies the CPU's results cannot show: the meta
    # device, the transfer counts and the crossings guard (tests/ddpg/test_devices.py) catch them
    Mutant(
        DEVICES,
        "out = torch.tensor(np.asarray(values), dtype=dtype, device=device)",
        "out = torch.tensor(np.asarray(values), dtype=dtype)",
        "device: to_device leaves host values on the host",
    ),
    Mutant(
        STREAMS,
        "return to_device([_signed(s) for s in seeds], self.device, torch.int64)",
        "return torch.tensor([_signed(s) for s in seeds], dtype=torch.int64)",
        "device: the stream keys stay on the host",
    ),
    Mutant(
        DDPG,
        "self._device_steps, self._device_busy = counters[0], counters[1].bool()",
        "self._device_steps, self._device_busy = counters[0], host_tensor(self.busy.copy())",
        "device: the busy mask stays on the host",
    ),
    Mutant(
        DDPG,
        "self.loss_sum += torch.where(mask, losses.double(), 0.0)",
        "self.loss_sum[:, mask] += losses.double()[:, mask]",
        "device: the loss sums index by a mask (the step waits for the device)",
    ),
    Mutant(
        DDPG,
        "flat_actor, flat_critic = self.learner.actor_flat(rows), self.learner.critic_flat(rows)\n"
        "        counts",
        "flat_actor, flat_critic = self.learner.actor_flat()[slots], "
        "self.learner.critic_flat()[slots]\n        counts",
        "device: an episode end copies every slot's parameters",
    ),
    Mutant(
        LEAN,
        "return params if rows is None else params.index_select(0, rows)",
        "return params",
        "device: the parameters of every slot come back for some",
    ),
    Mutant(
        DDPG,
        "        self.streams.set_seeds(slots, seeds)\n",
        "        for slot, seed in zip(slots, seeds, strict=True):\n"
        "            self.streams.set_seed(slot, seed)\n",
        "device: a refill sends every stream key once per slot",
    ),
    Mutant(
        DDPG,
        "        if self._device_steps is None:\n",
        "        if True:\n",
        "device: the counters go to the device every step",
    ),
    Mutant(
        DDPG,
        "        self.busy[slots] = False\n        self._counters_changed()\n",
        "        self.busy[slots] = False\n",
        "device: a stopped search's slot stays busy on the device",
    ),
    Mutant(
        REPLAY,
        '"rows": host_tensor(to_host(rows, temporary=True)),',
        '"rows": host_tensor(to_host(rows)),',
        "device: a checkpoint holds the replay rows twice",
    ),
    Mutant(
        REPLAY,
        "copy_to_device(part, out.data[i, : len(part)])",
        "out.data[i, : len(part)] = part",
        "device: a restore's replay rows cross uncounted",
    ),
    Mutant(
        DEVICES,
        "if temporary and is_host(tensor.device):",
        "if temporary:",
        "device: a temporary's memory is taken over on a device too",
    ),
    # --- DDPG: what F returns
    Mutant(
        DDPG,
        "search.result.theta, search.result.omega = theta.copy(), omega.copy()",
        "search.result.theta, search.result.omega = search.theta.copy(), omega.copy()",
        "start Actor returned with the trained fitness",
    ),
    Mutant(
        DDPG,
        "search.result.theta, search.result.omega = theta.copy(), omega.copy()",
        "search.result.theta, search.result.omega = theta.copy(), search.omega.copy()",
        "start Critic returned",
    ),
    Mutant(CONFIGS, "count_start: bool = False", "count_start: bool = True", "start counted"),
    Mutant(
        DDPG,
        "candidate = trained | hp.count_start",
        "candidate = trained | True",
        "warm-up evaluations counted",
    ),
    Mutant(
        DDPG,
        "best = score if counted else (-np.inf, -np.inf)",
        "best = score",
        "start's score kept as the bar to beat",
    ),
    Mutant(
        SLOTS,
        "        return candidate[0] > incumbent[0]",
        "        return candidate[0] >= incumbent[0]",
        "ties replace the best",
    ),
    Mutant(
        DDPG,
        "training = busy & (self.steps >= hp.warmup_steps)",
        "training = busy & (self.steps > hp.warmup_steps)",
        "one update fewer",
    ),
    Mutant(
        DDPG,
        "self.last_improvement[slot_of[id(search)]] = record.env_steps",
        "pass",
        "patience never reset by an improvement",
    ),
    Mutant(
        DDPG,
        "self.last_improvement[index] = self.hp.warmup_steps",
        "self.last_improvement[index] = 0",
        "patience window opens at step 0",
    ),
    Mutant(
        DDPG,
        "stale = (self.steps >= hp.min_steps) & (",
        "stale = (self.steps >= 0) & (",
        "min_steps ignored",
    ),
    Mutant(
        DDPG,
        "self.steps - self.last_improvement >= hp.patience_steps",
        "self.steps - self.last_improvement > hp.patience_steps",
        "patience off by one",
    ),
    Mutant(
        DDPG,
        "                result.omega = flat_critic[j].copy()\n"
        "                result.final_evaluation = True",
        "                result.omega = self.searches[slot].omega.copy()\n"
        "                result.final_evaluation = True",
        "final evaluation returns the start Critic",
    ),
    # --- Algorithm 2
    Mutant(
        BH,
        "return f_new >= f_best",
        "return f_new > f_best",
        "equal fitness rejected",
    ),
    Mutant(
        BH,
        "self.incumbent, self.incumbent_index, self.failures = optimum, trial.index, 0",
        "self.incumbent, self.incumbent_index = optimum, trial.index",
        "counter not reset on acceptance",
    ),
    Mutant(
        BH,
        "if self.failures >= config.tolerance:",
        "if self.failures > config.tolerance:",
        "T + 1 failures end a run",
    ),
    Mutant(
        BH,
        "elif len(self.trials) >= config.max_local_searches:",
        "elif len(self.trials) > config.max_local_searches:",
        "budget off by one",
    ),
    Mutant(
        BH,
        "noise = rng.uniform(-strength, strength, size=values.shape)",
        "noise = rng.uniform(0.0, strength, size=values.shape)",
        "one-sided perturbation",
    ),
    Mutant(
        BH,
        "return perturb(theta, strength, rng), perturb(omega, strength, rng)",
        "return perturb(theta, strength, rng), omega",
        "critic not perturbed",
    ),
    Mutant(
        BH,
        "rng = np.random.default_rng(trial_seeds(run_seed, index).perturbation)",
        "rng = np.random.default_rng(trial_seeds(run_seed, index).local_search)",
        "perturbation shares DDPG's stream",
    ),
    Mutant(
        BH,
        "parent = -1 if incumbent is None else state.incumbent_index",
        "parent = -1 if incumbent is None else index - 1",
        "wrong parent",
    ),
    Mutant(BH, "improved=optimum.improved,", "improved=True,", "every trial marked improved"),
    Mutant(
        BH,
        "return bool(self.fitness > self.start_fitness)",
        "return bool(self.fitness >= self.start_fitness)",
        "equal counted as improved",
    ),
    # --- physics
    Mutant(
        SIM,
        "friction = cfg.cart_friction * np.sign(x_dot)",
        "friction = -cfg.cart_friction * np.sign(x_dot)",
        "cart friction pushes",
    ),
    Mutant(
        SIM,
        "temp = (-drive - m * l * phi_dot**2 * sin + friction) / total",
        "temp = (-drive + m * l * phi_dot**2 * sin + friction) / total",
        "centripetal term sign",
    ),
    Mutant(
        SIM,
        "phi_ddot = (g * sin + cos * temp - cfg.hinge_friction",
        "phi_ddot = (-g * sin + cos * temp - cfg.hinge_friction",
        "gravity sign",
    ),
    Mutant(
        SIM,
        "phi_ddot = (g * sin + cos * temp - cfg.hinge_friction",
        "phi_ddot = (g * sin - cos * temp - cfg.hinge_friction",
        "cart-to-rod coupling sign",
    ),
    Mutant(
        SIM,
        "- cfg.hinge_friction * phi_dot / (m * l)) / (",
        "+ cfg.hinge_friction * phi_dot / (m * l)) / (",
        "hinge friction pushes",
    ),
    Mutant(
        SIM,
        "l * (4.0 / 3.0 - m * cos**2 / total)",
        "l * (4.0 / 3.0 + m * cos**2 / total)",
        "effective inertia term",
    ),
    Mutant(
        SIM,
        "x_ddot = (drive + m * l * (phi_dot**2 * sin - phi_ddot * cos) - friction) / total",
        "x_ddot = (drive + m * l * (phi_dot**2 * sin + phi_ddot * cos) - friction) / total",
        "rod-to-cart reaction sign",
    ),
    Mutant(
        SIM,
        "x_ddot = (drive + m * l * (phi_dot**2 * sin - phi_ddot * cos) - friction) / total",
        "x_ddot = (drive + m * l * (phi_dot**2 * sin - phi_ddot * cos) + friction) / total",
        "friction on the cart pushes",
    ),
    Mutant(
        SIM,
        "phi_ddot = 0.75 / l * (g * sin - x_ddot * cos)",
        "phi_ddot = 0.75 / l * (g * sin + x_ddot * cos)",
        "acceleration mode: coupling sign",
    ),
    Mutant(
        SIM,
        "phi_ddot = 0.75 / l * (g * sin - x_ddot * cos)",
        "phi_ddot = 0.75 / l * (-g * sin - x_ddot * cos)",
        "acceleration mode: gravity sign",
    ),
    Mutant(
        SIM,
        "drive = -cfg.motor_gain * motor_command(actions)",
        "drive = cfg.motor_gain * motor_command(actions)",
        "motor direction",
    ),
    Mutant(SIM, "h = cfg.dt / cfg.substeps", "h = cfg.dt", "substeps ignored"),
    Mutant(
        SIM,
        "else (drive - x_dot) / cfg.motor_tau",
        "else (drive - x_dot) / (2 * cfg.motor_tau)",
        "velocity motor: lag",
    ),
    Mutant(
        SIM,
        "else (drive - x_dot) / cfg.motor_tau",
        "else (x_dot - drive) / cfg.motor_tau",
        "velocity motor: sign",
    ),
    Mutant(
        SIM,
        "                x_dot, phi_dot = x_dot + h * x_ddot, phi_dot + h * phi_ddot\n"
        "                x, phi = x + h * x_dot, phi + h * phi_dot",
        "                x, phi = x + h * x_dot, phi + h * phi_dot\n"
        "                x_dot, phi_dot = x_dot + h * x_ddot, phi_dot + h * phi_ddot",
        "semi-implicit integrator made explicit",
    ),
    Mutant(
        SIM,
        "upright_each = (cos > self._cos_upright)",
        "upright_each = (cos < self._cos_upright)",
        "upright test inverted",
    ),
    Mutant(
        SIM,
        "upright_each = (cos > self._cos_upright) & running[:, None]",
        "upright_each = cos > self._cos_upright",
        "ended episodes keep scoring",
    ),
    Mutant(
        SIM,
        "reward = shaped + cfg.termination_penalty * terminated",
        "reward = shaped + cfg.termination_penalty * truncated",
        "penalty on truncation",
    ),
    Mutant(
        SIM,
        "reason = np.where((gaps > cfg.tether_length).any(axis=1), EndReason.TETHER, reason)",
        "reason = np.where((gaps > 2 * cfg.tether_length).any(axis=1), EndReason.TETHER, reason)",
        "tether rule",
    ),
    # --- the one rollout: defined arithmetic, both aggregations, conditioning, verify
    Mutant(
        NETS,
        "            h = sigmoid(h)",
        "            h = 0.5 * (1.0 + np.tanh(0.5 * h))",
        "one-rollout: a CPU-dispatched activation",
    ),
    Mutant(
        NETS,
        "h = np.add.accumulate(products, axis=2)[:, :, -1] + bias",
        "h = products.sum(axis=2) + bias",
        "one-rollout: a reduction of undefined order",
    ),
    Mutant(
        PMATH,
        "r = (x - k * LN2_HI) - k * LN2_LO",
        "r = x - k * LN2_HI",
        "one-rollout: exp's range reduction",
    ),
    Mutant(
        ROLLOUT,
        'fitness=mean if scoring.estimate == "robust" else head.fitness',
        'fitness=head.fitness if scoring.estimate == "robust" else mean',
        "one-rollout: estimates swapped",
    ),
    Mutant(
        SIM,
        "upright_all = upright_each.all(axis=1).astype(np.float64)",
        "upright_all = upright_each.any(axis=1).astype(np.float64)",
        "one-rollout: all rods read as any rod",
    ),
    Mutant(
        BEHAVIOUR,
        "fitness=float(result.fitness[row]),",
        "fitness=float(result.fitness_mean[row]),",
        "one-rollout: the descriptor's fitness from the other aggregation",
    ),
    Mutant(
        VERIFY,
        'if not _same(row["fitness"], expected):',
        'if False and not _same(row["fitness"], expected):',
        "one-rollout: verify skips the fitness",
    ),
    Mutant(
        VERIFY,
        'expected = replayed.robust_mean if estimate == "robust" else replayed.fitness',
        "expected = replayed.fitness",
        "one-rollout: verify compares the nominal fitness under robust",
    ),
    Mutant(
        VERIFY,
        "            if not _same(shown[name], value)",
        "            if False",
        "one-rollout: verify does not compare recordings",
    ),
    Mutant(
        VERIFY,
        'row["fitness"] <= end_step / steps + 1e-12',
        'row["fitness"] <= 1e9',
        "one-rollout: verify does not check the end step",
    ),
    Mutant(
        ROLLOUT,
        "offsets = np.repeat(nominal_offsets(config, seed or 0), batch_size, axis=1)",
        "offsets = np.repeat(nominal_offsets(config, 0), batch_size, axis=1)",
        "one-rollout: evaluate ignores its seed",
    ),
    Mutant(
        VERIFY,
        'relative and absolute tolerance."""\n        if exact:',
        'relative and absolute tolerance."""\n        if False:',
        "verify compares a b_* value within a tolerance on the sampling's own machine",
    ),
    Mutant(
        VERIFY,
        'if not _same(row["start_fitness"], score):',
        'if not _same(row["start_fitness"], row["start_fitness"]):',
        "verify never compares a start fitness",
    ),
    Mutant(
        VERIFY,
        "stored = read_optimum(optimum_path(folder, p, run, parent))",
        "stored = read_optimum(optimum_path(folder, p, run, max(parent - 1, 0)))",
        "verify rebuilds a start from another parent",
    ),
    Mutant(
        HOLDING,
        "all_up = trace.upright.all(axis=2)",
        "all_up = trace.upright[:, :, 0]",
        "holding: only the first rod must be upright",
    ),
    Mutant(
        HOLDING,
        "holds = full_length & (first >= 0) & stays",
        "holds = (first >= 0) & stays",
        "holding: an episode that ends early holds",
    ),
    Mutant(
        HOLDING,
        "eval_seed=scoring.eval_seed, ",
        "",
        "holding: rolled out from another start than the stored fitness's",
    ),
    Mutant(
        HOLDING,
        'accepted = trials[trials["accepted"].astype(bool)]',
        "accepted = trials",
        "holding: rejected optima measured as nodes",
    ),
    Mutant(
        POWER,
        "low = clopper_pearson(keys // (n + 2), keys % (n + 2), CONFIDENCE)[0][inverse]",
        "low = clopper_pearson(keys // (n + 1), keys % (n + 1), CONFIDENCE)[0][inverse]",
        "power: claim b's intervals of other pairs",
    ),
    # --- the compiled rollout (lonlib.task.kernels): its numpy definition is the oracle
    Mutant(
        KERNELS,
        "        m = math.copysign(0.0, b)",
        "        m = m",
        "kernels: mod keeps fmod's -0.0",
    ),
    Mutant(
        KERNELS,
        "    truncated = (not terminated) and steps_done >= ic[I_STEPS]",
        "    truncated = steps_done >= ic[I_STEPS]",
        "kernels: an end on the last step read as the step limit",
    ),
    Mutant(
        KERNELS,
        "    if tether:\n        reason = TETHER\n    if collision:\n        reason = COLLISION",
        "    if collision:\n        reason = COLLISION\n    if tether:\n        reason = TETHER",
        "kernels: tether before collision",
    ),
    Mutant(
        KERNELS,
        "gap > fc[F_TETHER]",
        "gap >= fc[F_TETHER]",
        "kernels: a gap of exactly the tether breaks it",
    ),
    Mutant(
        KERNELS,
        "                trace_upright[s, b] = False",
        "                trace_upright[s, b] = upright_each",
        "kernels: an ended row's trace keeps its last upright flags",
    ),
    Mutant(
        KERNELS,
        "            reward[b] = (shaped + fc[F_PENALTY] * 0.0) * 0.0",
        "            reward[b] = 0.0",
        "kernels: an ended NaN row's reward is 0, not numpy's NaN",
    ),
    Mutant(
        KERNELS,
        "            height = height * (1.0 - _minimum(speed, 1.0))",
        "            height = height * (1.0 - speed)",
        "kernels: slow-height's speed not capped at the sensor range",
    ),
    Mutant(
        KERNELS,
        "upright_each[c] = cos > fc[F_COS_UPRIGHT]",
        "upright_each[c] = cos >= fc[F_COS_UPRIGHT]",
        "kernels: a rod exactly at the upright angle counted upright",
    ),
    Mutant(
        GYM_DDPG,
        "        judged = (search.updates > 0 or hp.count_start) and (",
        "        judged = True and (",
        "Gymnasium DDPG: warm-up policies (the start) are judged as candidates",
    ),
    Mutant(
        GYM_DDPG,
        "            critic_loss, actor_loss = self.learner.update(self.replay.sample(indices))",
        "            critic_loss, actor_loss = np.zeros(self.slots), np.zeros(self.slots)",
        "Gymnasium DDPG: no update is made",
    ),
    Mutant(
        GYM_DDPG,
        "                if search.updates == 0 and search.dirty:  # back to its start",
        "                if False:",
        "Gymnasium DDPG: a refilled slot trains from what the batch made of it in its warm-up",
    ),
    Mutant(
        GYM_DDPG,
        "            rng = np.random.default_rng([seeds[j], SEARCH_STREAM])",
        "            rng = np.random.default_rng([seeds[0], SEARCH_STREAM])",
        "Gymnasium DDPG: the searches of a batch share one seed",
    ),
    Mutant(
        GYM_DDPG,
        "int(sizes[slot]), size=hp.batch_size)",
        "int(sizes[0]), size=hp.batch_size)",
        "Gymnasium DDPG: a slot draws its replay indices by another slot's buffer size",
    ),
    Mutant(
        GYM_DDPG,
        "                and search.steps - search.last_improvement >= hp.patience_steps",
        "                and search.steps - search.last_improvement > hp.patience_steps",
        "Gymnasium DDPG: patience runs one step longer",
    ),
    Mutant(
        GYM_DDPG,
        "SlotEnvironmentError(str(error), search.tag if search else None)",
        "SlotEnvironmentError(str(error), None)",
        "Gymnasium DDPG: a failing environment is not traced to its search",
    ),
    Mutant(
        VERIFY,
        "report.findings.extend(\n"
        "                _check_task_descriptor(task, row, theta, severity, behaviour_differs)\n"
        "            )",
        "pass",
        "verify: a Gymnasium task's stored behaviour is not replayed",
    ),
    Mutant(
        VERIFY,
        'if (stored.get(name) != value if name == "label" else differs(stored.get(name), value))',
        'if (False if name == "label" else differs(stored.get(name), value))',
        "verify: a Gymnasium task's stored label is not compared",
    ),
    Mutant(
        GYM_BEHAVIOUR,
        "        self.observations.append(np.array(observation, dtype=np.float64))\n"
        "        return observation, info",
        "        return observation, info",
        "Gymnasium descriptor: the trace misses the observation after reset",
    ),
    Mutant(
        GYM_BEHAVIOUR,
        "        if not isinstance(number, (int, float)) or not math.isfinite(float(number)):",
        "        if not isinstance(number, (int, float)):",
        "Gymnasium descriptor: a NaN value is stored",
    ),
    Mutant(
        GYM_DDPG,
        "search.steps // hp.judge_every > previous_end // hp.judge_every",
        "search.steps // hp.judge_every >= previous_end // hp.judge_every",
        "Gymnasium DDPG: with judge_every, every episode's end is judged",
    ),
    Mutant(
        GYM_DDPG,
        "                last_improvement=hp.warmup_steps,",
        "                last_improvement=0,",
        "Gymnasium DDPG: the patience window opens at step 0, before anything is judged",
    ),
    Mutant(
        GYM_DDPG,
        "                search.last_improvement = max(search.steps, hp.warmup_steps)",
        "                pass",
        "Gymnasium DDPG: an improvement does not restart the patience",
    ),
    Mutant(
        GYM_DDPG,
        "                result.theta, result.omega, result.final_evaluation = actor, critic, True",
        "                result.final_evaluation = True",
        "Gymnasium DDPG: a search that judged nothing returns its start, not its trained Actor",
    ),
    Mutant(
        GYM_DDPG,
        "                    result.fitness = self._greedy(actor)[0]",
        "                    result.fitness = result.start_fitness",
        "Gymnasium DDPG: a search that judged nothing is given its start's fitness",
    ),
    Mutant(
        GYM_DDPG,
        "            self.envs[slot].renew()",
        "            pass",
        "Gymnasium DDPG: a refilled slot trains in the environment the last search used",
    ),
    Mutant(
        GYM_DDPG,
        "            search.episode_return += float(rewards[slot])",
        "            search.episode_return = float(rewards[slot])",
        "Gymnasium DDPG: the history's episode return is its last reward",
    ),
    Mutant(
        GYM_DDPG,
        "        search.losses = []",
        "        pass",
        "Gymnasium DDPG: the history's losses average every episode so far",
    ),
    Mutant(
        GYM_DESCRIPTORS,
        "    up = cos[1:] >= UPRIGHT_COS",
        "    up = cos[1:] > UPRIGHT_COS",
        "Pendulum-v1 descriptor: exactly 20 degrees from upright is not up",
    ),
    Mutant(
        GYM_DESCRIPTORS,
        "    up = cos[1:] >= UPRIGHT_COS",
        "    up = cos[:-1] >= UPRIGHT_COS",
        "Pendulum-v1 descriptor: reset's observation counts, the last step's does not",
    ),
    Mutant(
        GYM_DESCRIPTORS,
        "    last = up[-max(1, len(up) // 4) :]",
        "    last = up[-(len(up) // 4) :]",
        "Pendulum-v1 descriptor: an episode under 4 steps has no last quarter (the whole one)",
    ),
    Mutant(
        GYM_DESCRIPTORS,
        "    if last.all():",
        "    if last.any():",
        "Pendulum-v1 descriptor: up once in the last quarter counts as holding",
    ),
    Mutant(
        GYM_DESCRIPTORS,
        "    elif abs(turns) >= 2:",
        "    elif turns >= 2:",
        "Pendulum-v1 descriptor: spinning one way only",
    ),
    Mutant(
        GYM_DESCRIPTORS,
        "    elif abs(turns) >= 2:",
        "    elif abs(turns) >= 3:",
        "Pendulum-v1 descriptor: spinning from three turns",
    ),
    Mutant(
        GYM_DESCRIPTORS,
        '    if last.all():\n        label = "swings up and holds"\n'
        '    elif abs(turns) >= 2:\n        label = "spins"',
        '    if abs(turns) >= 2:\n        label = "spins"\n'
        '    elif last.all():\n        label = "swings up and holds"',
        "Pendulum-v1 descriptor: spinning outranks holding at the end",
    ),
    Mutant(
        GYM_DESCRIPTORS,
        "    if position.max() >= MOUNTAIN_CAR_GOAL:",
        "    if position.max() > MOUNTAIN_CAR_GOAL:",
        "Mountain car descriptor: exactly at the goal is not reaching it",
    ),
    Mutant(
        GYM_DESCRIPTORS,
        "    elif fuel < STAY_PUT_FUEL:",
        "    elif fuel <= STAY_PUT_FUEL:",
        "Mountain car descriptor: one unit of fuel still stays put",
    ),
    Mutant(
        GYM_DESCRIPTORS,
        "    fuel = float(np.sum(trace.actions**2))",
        "    fuel = float(np.sum(np.abs(trace.actions)))",
        "Mountain car descriptor: fuel is not the squared actions the reward charges",
    ),
    Mutant(
        GYM_DESCRIPTORS,
        '        "position_range": float(position.max() - position.min()),',
        '        "position_range": float(position.max() - position[1:].min()),',
        "Mountain car descriptor: the range leaves out where reset put the car",
    ),
    Mutant(
        VERIFY,
        "math.isclose(float(stored), replayed, rel_tol=tolerance, abs_tol=tolerance)",
        "math.isclose(float(stored), replayed, rel_tol=0.0, abs_tol=tolerance)",
        "verify: a b_* value replayed elsewhere within an absolute tolerance only",
    ),
    Mutant(
        VERIFY,
        "        report.findings.extend(_undescribed_behaviour(rows, mismatch))",
        "        pass",
        "verify: behaviour stored under no descriptor is not reported",
    ),
    Mutant(
        VERIFY,
        "    report.descriptor_checked = False",
        "    pass",
        "verify: a descriptor that does not import leaves the verification complete",
    ),
    Mutant(
        RUNS,
        "    if names != stored:",
        "    if False:",
        "a run's trial is saved with other behaviour columns than its stored trials",
    ),
    Mutant(
        RUNS,
        "        columns = stored_trial_columns(out, skip=trials_path(out, p, run))",
        "        columns = None",
        "a new run's first trial is saved with other behaviour columns than the other runs'",
    ),
    Mutant(
        RUNS,
        "    if columns is not None and behaviour_names(columns) != names:",
        "    if False:",
        "a session starts with a descriptor whose names the stored trials do not have",
    ),
    Mutant(
        RUNS,
        "    if seal.sealed:",
        "    if False:",
        "a descriptor written into a sealed manifest by hand reads as a changed descriptor",
    ),
    Mutant(
        CLI_RUN,
        "        minutes = CHECKPOINT_SECONDS / 60",
        "        minutes = 0",
        "lonlib run writes no in-flight checkpoints unless told to",
    ),
    Mutant(
        IMPORTS,
        "    except (Exception, SystemExit) as error:  # the user's module raised (or exited)",
        "    except ZeroDivisionError as error:",
        "a descriptor module that raises while imported is a traceback",
    ),
]


def run_guards(tests: list[str], workdir: Path, python: str) -> str:
    """Run ``tests`` (pytest, stopping at the first failure) in ``workdir``: "passed",
    "failed" or "timeout"."""
    try:
        proc = subprocess.run(
            [python, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", *tests],
            cwd=workdir,
            capture_output=True,
            text=True,
            timeout=900,
        )
    except subprocess.TimeoutExpired:
        return "timeout"
    return "passed" if proc.returncode == 0 else "failed"


def run_mutant(mutant: Mutant, workdir: Path, python: str) -> tuple[str, float]:
    """Apply one mutant inside ``workdir``, run its guard tests, restore; return the outcome."""
    target = workdir / mutant.path
    original = target.read_text()
    if original.count(mutant.old) != 1:
        return "STALE (text not found exactly once)", 0.0
    target.write_text(original.replace(mutant.old, mutant.new))
    start = time.perf_counter()
    try:
        outcome = {"passed": "SURVIVED", "failed": "killed", "timeout": "killed (timeout)"}[
            run_guards(GUARDS[mutant.path], workdir, python)
        ]
    finally:
        target.write_text(original)
    return outcome, time.perf_counter() - start


def copy_committed_data(workdir: Path) -> None:
    """git's files under ``data/`` (the committed experiments and studies, which guard tests
    read), ``benchmarks/measured/`` (the measured costs the claims' power table reads),
    ``configs/`` (the studies' grids) and ``notebooks/`` (a calibration guard runs one) into
    ``workdir``, so that a mutant never reads or writes the working tree's."""
    listed = subprocess.run(
        ["git", "ls-files", "-z", "data", "benchmarks/measured", "configs", "notebooks"],
        cwd=ROOT,
        capture_output=True,
        check=True,
    ).stdout
    for name in filter(None, listed.split(b"\0")):
        target = workdir / os.fsdecode(name)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / os.fsdecode(name), target)


def baseline_failures(
    selected: list[Mutant], free: queue.Queue[Path], jobs: int, python: str
) -> list[str]:
    """The guard test sets of ``selected`` that fail on the unmutated copy."""
    sets = sorted({tuple(GUARDS[m.path]) for m in selected})

    def one(tests: tuple[str, ...]) -> str:
        workdir = free.get()
        try:
            return run_guards(list(tests), workdir, python)
        finally:
            free.put(workdir)

    with ThreadPoolExecutor(jobs) as pool:
        outcomes = list(pool.map(one, sets))
    return [
        " ".join(tests)
        for tests, outcome in zip(sets, outcomes, strict=True)
        if outcome != "passed"
    ]


def main(argv: list[str]) -> int:
    """Run every mutant (``--jobs N`` at a time; a word filters by description, ``--path
    TEXT`` by the mutated file's path)."""
    jobs, where, baseline = 1, "", "--no-baseline" not in argv
    argv = [a for a in argv if a != "--no-baseline"]
    if "--jobs" in argv:
        at = argv.index("--jobs")
        jobs = int(argv[at + 1])
        argv = argv[:at] + argv[at + 2 :]
    if "--path" in argv:
        at = argv.index("--path")
        where = argv[at + 1]
        argv = argv[:at] + argv[at + 2 :]
    if argv and argv[0] in ("-h", "--help"):
        print(
            __doc__.strip()
            + "\n\nusage: python tests/mutants.py [WORDS] [--path TEXT] [--jobs N] [--no-baseline]"
        )
        return 0
    selected = [m for m in MUTANTS if (not argv or argv[0] in m.why) and where in str(m.path)]
    # a guard that is not a file would fail pytest and count every mutant as killed
    missing = sorted({t for m in selected for t in GUARDS[m.path] if not (ROOT / t).is_file()})
    if missing:
        print(f"guard test files not found (keep GUARDS in step with tests/): {missing}")
        return 1
    with tempfile.TemporaryDirectory(prefix="lonlib-mutants-") as tmp:
        free: queue.Queue[Path] = queue.Queue()
        for slot in range(jobs):
            workdir = Path(tmp) / str(slot)
            shutil.copytree(ROOT / "lonlib", workdir / "lonlib")
            shutil.copytree(ROOT / "tests", workdir / "tests")
            shutil.copy(ROOT / "pyproject.toml", workdir)
            copy_committed_data(workdir)
            free.put(workdir)
        failing = baseline_failures(selected, free, jobs, sys.executable) if baseline else []
        if failing:
            print(f"guard tests fail without any mutant (fix them first): {failing}")
            return 1

        def one(mutant: Mutant) -> tuple[str, float]:
            workdir = free.get()
            try:
                return run_mutant(mutant, workdir, sys.executable)
            finally:
                free.put(workdir)

        survivors = 0
        with ThreadPoolExecutor(jobs) as pool:
            for number, (mutant, (outcome, seconds)) in enumerate(
                zip(selected, pool.map(one, selected), strict=True), 1
            ):
                survivors += not outcome.startswith("killed")
                where = f"{mutant.path}: {mutant.why}"
                print(
                    f"{number:2d}/{len(selected)} {outcome:9s} {seconds:5.1f} s  {where}",
                    flush=True,
                )
    print(f"{len(selected) - survivors} of {len(selected)} mutants killed")
    return 1 if survivors else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
