"""``python -m soft_snake_gym.cli``: the ``soft-snake`` command."""

import sys

from soft_snake_gym.cli import main

sys.exit(main())
