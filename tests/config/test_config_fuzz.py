"""Property-based configuration checks (hypothesis) over YAML-shaped input.

Every value either gives a configuration that round-trips through YAML and JSON unchanged,
or is refused with a ValueError naming its field; documented out-of-range values, values of
the wrong kind and unknown keys are always refused. Nothing here computes: a configuration
is refused while it is being built, before any run can start.
"""

import json
import math
import tempfile
from dataclasses import fields
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, example, given, reject, settings
from hypothesis import strategies as st

from lonlib.config import DDPGConfig, ExperimentConfig, PendulumConfig, load_config

SECTIONS = {None: ExperimentConfig, "env": PendulumConfig, "ddpg": DDPGConfig}
FIELDS = {
    (section, f.name): f.type if isinstance(f.type, str) else f.type.__name__
    for section, cls in SECTIONS.items()
    for f in fields(cls)
    if not (section is None and f.name in ("env", "ddpg"))
}

FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
ROUND_TRIPS = settings(FUZZ, max_examples=60)  # YAML in pure Python: ~20 ms an example

# What a YAML file can hold.
scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(),
    st.integers(min_value=2**63 - 2, max_value=2**1100),
    st.floats(),
    st.floats(min_value=-20, max_value=20),
    st.text(max_size=8),
)
yaml_values = st.recursive(
    scalars,
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner),
    max_leaves=4,
)


def _not_a_mapping(value) -> bool:
    return value is not None and not isinstance(value, dict)


def with_value(section: str | None, name: str, value) -> dict:
    """A configuration mapping that sets one field."""
    return {name: value} if section is None else {section: {name: value}}


def field_of(config: ExperimentConfig, section: str | None, name: str):
    return getattr(config if section is None else getattr(config, section), name)


def assert_round_trips(config: ExperimentConfig) -> None:
    """Through YAML (what users write), JSON (the manifest) and a YAML file on disk."""
    # PyYAML's emitter writes YAML's own line breaks (NEL, LS, PS) raw into a plain scalar,
    # which its reader folds to a space: a PyYAML limitation, so such text is written escaped.
    text = json.dumps(config.to_dict(), ensure_ascii=False)
    raw = not any(mark in text for mark in "\x85\u2028\u2029")
    as_yaml = yaml.safe_dump(config.to_dict(), allow_unicode=raw)
    assert ExperimentConfig.from_mapping(yaml.safe_load(as_yaml)) == config
    as_json = json.dumps(config.to_dict())
    assert ExperimentConfig.from_mapping(json.loads(as_json)) == config
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "config.yaml"
        path.write_text(as_yaml, encoding="utf-8")
        assert load_config(path) == config
    assert ExperimentConfig.from_mapping(config.to_dict()).to_dict() == config.to_dict()


@settings(FUZZ, max_examples=400)
@given(field=st.sampled_from(sorted(FIELDS, key=str)), value=yaml_values)
def test_any_value_is_taken_as_given_or_refused_naming_its_field(field, value):
    section, name = field
    try:
        config = ExperimentConfig.from_mapping(with_value(section, name, value))
    except ValueError as error:
        assert name in str(error)
        return
    stored = field_of(config, section, name)
    if name == "perturbations":
        assert list(stored) == [float(p) for p in value]
    else:
        assert stored == value and type(stored) is type(value)
    assert_round_trips(config)


def ints_outside(low: int, high: int | None = None):
    """Integers below ``low`` or above ``high``."""
    above = st.integers(min_value=high + 1) if high is not None else st.nothing()
    return st.integers(max_value=low - 1) | above


def floats_below(low: float, or_equal: bool = False):
    """Floats below ``low`` (or equal to it), -inf included."""
    return st.floats(max_value=low, exclude_max=not or_equal, allow_nan=False)


def floats_above(high: float):
    """Floats above ``high``, inf included."""
    return st.floats(min_value=high, exclude_min=True, allow_nan=False)


# The documented ranges (README, SPEC): each must be refused outside, by name.
RANGES = {
    (None, "runs"): ints_outside(1, 1_000_000),
    (None, "tolerance"): ints_outside(1, 10_000),
    (None, "max_local_searches"): ints_outside(1, 1_000_000),
    (None, "seed"): ints_outside(0, 2**63 - 1),
    ("env", "n_carts"): ints_outside(1, 5),
    ("env", "steps"): ints_outside(1, 3000),
    ("env", "substeps"): ints_outside(1, 1000),
    ("env", "upright_angle"): floats_below(0.0, or_equal=True) | floats_above(math.pi),
    ("env", "initial_noise"): floats_below(0.0) | floats_above(0.5),
    ("env", "initial_angle"): floats_below(0.0) | st.floats(min_value=2 * math.pi, allow_nan=False),
    ("env", "termination_penalty"): floats_above(0.0),
    ("ddpg", "batch_size"): ints_outside(1),
    ("ddpg", "buffer_size"): ints_outside(1),
    ("ddpg", "max_steps"): ints_outside(1),
    ("ddpg", "min_steps"): ints_outside(0),
    ("ddpg", "threads"): ints_outside(1, 256),
    ("ddpg", "learning_rate"): floats_below(0.0, or_equal=True) | floats_above(1.0),
    ("ddpg", "gamma"): floats_below(0.0) | floats_above(1.0),
    ("ddpg", "tau"): floats_below(0.0, or_equal=True) | floats_above(1.0),
    ("ddpg", "noise_std"): floats_below(0.0) | floats_above(1.0),
}
for _name in (
    "gravity",
    "cart_mass",
    "pole_mass",
    "pole_half_length",
    "dt",
    "motor_gain",
    "cart_width",
    "tether_length",
    "velocity_range",
    "angular_velocity_range",
):
    RANGES["env", _name] = floats_below(0.0, or_equal=True)
for _name in ("cart_friction", "hinge_friction", "track_half_length_per_cart"):
    RANGES["env", _name] = floats_below(0.0)

# Values of the wrong kind for each annotated kind (never valid, whatever the range).
WRONG_KIND = {
    "int": st.one_of(
        st.booleans(),
        st.floats().filter(lambda v: not float(v).is_integer()),
        st.floats(allow_nan=False).filter(lambda v: float(v).is_integer()),
        st.text(max_size=4),
        st.none(),
        st.lists(st.integers(), max_size=2),
    ),
    "float": st.one_of(
        st.booleans(),
        st.sampled_from([math.nan, math.inf, -math.inf, 10**400, -(10**400)]),
        st.text(max_size=4),
        st.none(),
        st.lists(st.floats(), max_size=2),
        st.dictionaries(st.text(max_size=2), st.integers(), max_size=2),
    ),
    "str": st.one_of(st.booleans(), st.integers(), st.floats(), st.none(), st.lists(st.text())),
    "bool": st.one_of(st.integers(), st.floats(), st.text(max_size=4), st.none()),
}


@FUZZ
@given(data=st.data())
def test_documented_out_of_range_values_are_refused_naming_the_field(data):
    section, name = data.draw(st.sampled_from(sorted(RANGES, key=str)), label="field")
    value = data.draw(RANGES[section, name], label="value")
    with pytest.raises(ValueError, match=name):
        ExperimentConfig.from_mapping(with_value(section, name, value))


@FUZZ
@given(data=st.data())
def test_values_of_the_wrong_kind_are_refused_naming_the_field(data):
    typed = sorted((k for k, kind in FIELDS.items() if kind in WRONG_KIND), key=str)
    section, name = data.draw(st.sampled_from(typed), label="field")
    value = data.draw(WRONG_KIND[FIELDS[section, name]], label="value")
    with pytest.raises(ValueError, match=name):
        ExperimentConfig.from_mapping(with_value(section, name, value))


@FUZZ
@given(data=st.data())
def test_perturbations_must_be_a_list_of_distinct_numbers_in_0_10(data):
    value = data.draw(
        st.one_of(
            st.just([]),
            scalars,
            st.lists(st.floats(1e-6, 10), min_size=1, max_size=3).map(lambda v: v + v[:1]),
            st.lists(st.booleans() | st.text(max_size=3).filter(_not_a_number), min_size=1),
        )
    )
    with pytest.raises(ValueError, match="perturbations"):
        ExperimentConfig.from_mapping({"perturbations": value})


def _not_a_number(text: str) -> bool:
    try:
        return not math.isfinite(float(text))
    except ValueError:
        return True


@FUZZ
@given(
    section=st.sampled_from(list(SECTIONS)),
    keys=st.lists(
        st.text(min_size=1, max_size=12) | st.integers() | st.booleans(),
        min_size=1,
        max_size=3,
        unique_by=repr,
    ),
)
def test_unknown_keys_are_refused_by_name(section, keys):
    known = {f.name for f in fields(SECTIONS[section])} | ({"base"} if section is None else set())
    keys = [k for k in keys if k not in known]
    if not keys:
        reject()
    values = dict.fromkeys(keys, 1)  # 0 == False and 1 == True: one key each in a mapping
    with pytest.raises(ValueError, match="unknown") as refused:
        ExperimentConfig.from_mapping(values if section is None else {section: values})
    for key in values:
        assert repr(key) in str(refused.value)


@FUZZ
@given(section=st.sampled_from(["env", "ddpg"]), value=yaml_values.filter(_not_a_mapping))
def test_sections_must_be_mappings(section, value):
    with pytest.raises(ValueError, match=section):
        ExperimentConfig.from_mapping({section: value})


def _names():
    return st.from_regex(r"[A-Za-z0-9_-]{1,16}", fullmatch=True).filter(
        lambda n: n.replace("-", "").replace("_", "") != ""
    )


valid_mappings = st.fixed_dictionaries(
    {},
    optional={
        "base": st.sampled_from(["quick", "paper"]),
        "name": _names(),
        "perturbations": st.lists(st.floats(1e-9, 10), min_size=1, max_size=4, unique=True),
        "runs": st.integers(1, 1_000_000),
        "tolerance": st.integers(1, 10_000),
        "max_local_searches": st.integers(1, 1_000_000),
        "seed": st.integers(0, 2**63 - 1),
        "note": st.text(max_size=40),
        "env": st.fixed_dictionaries(
            {},
            optional={
                "n_carts": st.integers(1, 5),
                "gravity": st.floats(0.1, 30),
                "dt": st.floats(1e-4, 0.1),
                "steps": st.integers(1, 3000),
                "integrator": st.sampled_from(["euler", "semi-implicit"]),
                "motor": st.sampled_from(["force", "acceleration"]),
                "fitness_mode": st.sampled_from(["all", "mean"]),
                "reward": st.sampled_from(["height", "upright"]),
                "upright_angle": st.floats(1e-3, math.pi),
                "initial_noise": st.floats(0, 0.5),
                "termination_penalty": st.floats(-100, 0),
                "tether_length": st.floats(1.2, 5),
            },
        ),
        "ddpg": st.fixed_dictionaries(
            {},
            optional={
                "batch_size": st.integers(1, 10_000),
                "learning_rate": st.floats(1e-6, 1),
                "gamma": st.floats(0, 1),
                "noise_std": st.floats(0, 1),
                "plateau_tiebreak": st.booleans(),
                "max_steps": st.integers(60_000, 10**9),
                "device": st.sampled_from(["cpu", "cuda", "cuda:1"]),
            },
        ),
    },
)


@ROUND_TRIPS
@given(mapping=valid_mappings)
@example(mapping={"base": "quick", "ddpg": {}, "env": {}, "note": "\x85"})  # found in a clone
@example(mapping={"base": "quick", "note": "φ \u2028 é"})
def test_valid_configurations_round_trip_unchanged(mapping):
    try:
        config = ExperimentConfig.from_mapping(mapping)
    except ValueError:
        reject()  # a combination outside a cross-field rule (e.g. the track length)
    for key, value in mapping.items():
        if key in ("env", "ddpg"):
            for name, setting in value.items():
                assert getattr(getattr(config, key), name) == setting
        elif key == "perturbations":
            assert list(config.perturbations) == value
        elif key != "base":
            assert getattr(config, key) == value
    assert_round_trips(config)
