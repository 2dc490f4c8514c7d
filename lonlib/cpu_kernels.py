"""Moved to :mod:`lonlib.util.cpu_kernels`; this name stays importable for code written before the
subpackages (the golden test among it): it is that module, not a copy."""

import sys

from lonlib.util import cpu_kernels as moved

sys.modules[__name__] = moved
