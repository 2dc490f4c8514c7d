"""Every configuration of lonlib, whole and valid the moment it exists (no torch): the task's
physics (:class:`PendulumConfig`), how a policy is scored (:class:`Scoring`), Algorithm 2's
inputs (:class:`BasinHoppingConfig`), DDPG's hyperparameters (:class:`DDPGConfig`), an
experiment (:class:`ExperimentConfig`, the named ones and YAML files, and its Gymnasium task,
:class:`GymnasiumTaskConfig`) and a calibration study
(:class:`CalibrationConfig`, its :class:`Cell` grid and :class:`StartSpread`). Each checks its
fields when it is made and raises ``ValueError`` naming the field; the stored forms
(``to_dict``, ``from_mapping``) are those of the experiments and studies on disk."""

from lonlib.config.calibration import (
    DEFAULT_CELLS,
    CalibrationConfig,
    Cell,
    StartSpread,
    grid,
    load_calibration,
    named_calibration,
    with_overrides,
)
from lonlib.config.ddpg import LEARNERS, DDPGConfig
from lonlib.config.experiment import (
    EXECUTORS,
    NAMED_CONFIGS,
    ExperimentConfig,
    load_config,
    named_config,
)
from lonlib.config.pendulum import PendulumConfig
from lonlib.config.scoring import Scoring
from lonlib.config.search import BasinHoppingConfig
from lonlib.config.task import GymnasiumTaskConfig

__all__ = [
    "BasinHoppingConfig",
    "CalibrationConfig",
    "Cell",
    "DDPGConfig",
    "DEFAULT_CELLS",
    "EXECUTORS",
    "ExperimentConfig",
    "GymnasiumTaskConfig",
    "LEARNERS",
    "NAMED_CONFIGS",
    "PendulumConfig",
    "Scoring",
    "StartSpread",
    "grid",
    "load_calibration",
    "load_config",
    "named_calibration",
    "named_config",
    "with_overrides",
]
