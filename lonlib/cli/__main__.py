"""``python -m lonlib.cli``: the same as the ``lonlib`` command."""

from lonlib.cli import main

if __name__ == "__main__":
    main()
