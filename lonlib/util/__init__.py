"""Small helpers every layer may use: field checks, portable float64 math, progress bars,
the data folder, generated Markdown tables, the pinned CPU kernels."""

from lonlib.util.cpu_kernels import (
    CpuKernelWarning,
    expected_torch_capability,
    pin_torch_cpu_kernels,
    torch_cpu_capability,
)
from lonlib.util.imports import import_function
from lonlib.util.labels import p_label
from lonlib.util.messages import show_lonlib_messages
from lonlib.util.paths import project_path, project_root
from lonlib.util.progress import progress_bar
from lonlib.util.readme_tables import splice, splice_generated
from lonlib.util.validation import check_choice, check_range

__all__ = [
    "CpuKernelWarning",
    "check_choice",
    "check_range",
    "expected_torch_capability",
    "import_function",
    "p_label",
    "pin_torch_cpu_kernels",
    "progress_bar",
    "project_path",
    "project_root",
    "show_lonlib_messages",
    "splice",
    "splice_generated",
    "torch_cpu_capability",
]
