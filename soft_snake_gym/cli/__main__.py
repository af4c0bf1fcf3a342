"""``python -m soft_snake_gym.cli``: the ``soft-snake`` command."""

import sys

from soft_snake_gym.cli import main

if __name__ == "__main__":  # not in the worker processes that re-import the main module
    sys.exit(main())
