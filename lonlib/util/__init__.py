"""Small helpers every layer may use: field checks, portable float64 math, progress bars,
the data folder, generated Markdown tables, the pinned CPU kernels."""

from lonlib.util.cpu_kernels import (
    CAPABILITY_VARIABLE,
    PINNED_CAPABILITY,
    CpuKernelWarning,
    cpu_record,
    expected_torch_capability,
    is_x86_64,
    numpy_cpu_features,
    pin_torch_cpu_kernels,
    torch_cpu_capability,
    unpinned_message,
)
from lonlib.util.deprecation import (
    renamed_keyword,
)
from lonlib.util.messages import (
    show_lonlib_messages,
)
from lonlib.util.paths import (
    project_path,
    project_root,
)
from lonlib.util.plain_data import (
    StateLayoutError,
    config_from_plain,
    generator_from_state,
    generator_state,
    plain_bool,
    plain_dict,
    plain_float,
    plain_int,
    plain_list,
    plain_str,
    short_repr,
)
from lonlib.util.portable_math import (
    cos,
    exp,
    sigmoid,
    sin,
    sin_cos,
)
from lonlib.util.progress import (
    in_jupyter_server_kernel,
    progress_bar,
)
from lonlib.util.readme_tables import (
    splice,
    splice_generated,
)
from lonlib.util.validation import (
    check_choice,
    check_field_types,
    check_keys,
    check_name,
    check_range,
    is_finite,
    read_yaml_mapping,
)

__all__ = [
    "CAPABILITY_VARIABLE",
    "CpuKernelWarning",
    "PINNED_CAPABILITY",
    "StateLayoutError",
    "check_choice",
    "check_field_types",
    "check_keys",
    "check_name",
    "check_range",
    "config_from_plain",
    "cos",
    "cpu_record",
    "exp",
    "expected_torch_capability",
    "generator_from_state",
    "generator_state",
    "in_jupyter_server_kernel",
    "is_finite",
    "is_x86_64",
    "numpy_cpu_features",
    "pin_torch_cpu_kernels",
    "plain_bool",
    "plain_dict",
    "plain_float",
    "plain_int",
    "plain_list",
    "plain_str",
    "progress_bar",
    "project_path",
    "project_root",
    "read_yaml_mapping",
    "renamed_keyword",
    "short_repr",
    "show_lonlib_messages",
    "sigmoid",
    "sin",
    "sin_cos",
    "splice",
    "splice_generated",
    "torch_cpu_capability",
    "unpinned_message",
]
