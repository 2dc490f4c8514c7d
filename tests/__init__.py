"""lonlib's tests, mirroring the package: ``tests/<name>/`` tests ``lonlib/<name>`` (``util``,
``config``, ``task``, ``search``, ``ddpg``, ``sb3``, ``storage``, ``experiment``, ``lon``,
``analysis``, ``calibration``, ``cli``), ``tests/notebooks/`` the notebooks and
``lonlib.notebook_run``, and ``tests/project/`` the project as a whole (docs, layout, public
names, types); each folder's ``__init__.py`` says what it holds. ``conftest.py`` holds the
fixtures and helpers shared by all; ``mutants.py`` is ``make mutants``' script, not a test.
pytest imports the tests with ``--import-mode=importlib`` (``pyproject.toml``): a helper shared
between files is imported by its package path (``from tests.lon.test_lon import HAND``).
"""
