"""Moved to :mod:`lonlib.search.algorithm`; this name stays importable for code written before the
subpackages (the golden test among it): it is that module, not a copy."""

import sys

from lonlib.search import algorithm as moved

sys.modules[__name__] = moved
