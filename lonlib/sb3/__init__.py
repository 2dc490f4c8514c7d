"""Stable-Baselines3's TD3, SAC and DDPG as Algorithm 2's local search ``F`` on a Gymnasium
task (``task.search``: ``sb3-td3``, ``sb3-sac``, ``sb3-ddpg``; the optional extra
``lonlib[sb3]``).

An SB3 model with the paper's shapes (three hidden layers of 20 sigmoids, actor and critics)
starts from Algorithm 2's Actor ``theta`` and Critic ``omega`` (:mod:`lonlib.sb3.params`
converts between lonlib's flat layout and SB3's modules), trains on the task's environment
(:mod:`lonlib.sb3.env`) and is judged by the task's one fitness function, its greedy episode,
at episode ends as lonlib's DDPG judges (:mod:`lonlib.sb3.callback`); :mod:`lonlib.sb3.search`
returns the best judged policy. Importing this package does not import SB3: the modules that
do are imported when a search is made (:func:`check_search` says before any compute whether
they can be).
"""

from __future__ import annotations

import importlib.util

SB3_SEARCHES = ("sb3-td3", "sb3-sac", "sb3-ddpg")
"""The task searches that are Stable-Baselines3's (``task.search``)."""

MISSING = (
    "task.search {search!r} needs Stable-Baselines3, which is not installed: "
    "pip install 'lonlib[sb3]'"
)


def check_search(search: str, device: str = "cpu") -> None:
    """ValueError in one line, before any compute, when the task's search ``search`` cannot
    run here: an SB3 search without Stable-Baselines3 installed (naming the extra), or on
    another device than the CPU (``ddpg.device``). lonlib's own ``ddpg`` always can."""
    if search not in SB3_SEARCHES:
        return
    try:
        found = importlib.util.find_spec("stable_baselines3") is not None
    except (ImportError, ValueError):  # a parent that fails, or a module without a spec
        found = False
    if not found:
        raise ValueError(MISSING.format(search=search))
    if device != "cpu":
        raise ValueError(
            f"ddpg.device {device!r}: the Stable-Baselines3 searches ({search!r}) run on the "
            "CPU; set ddpg.device: cpu"
        )


__all__ = ["MISSING", "SB3_SEARCHES", "check_search"]
