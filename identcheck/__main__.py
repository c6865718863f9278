"""``python -m identcheck``: the same command line as the ``identcheck`` script."""
import sys

from .cli import main

sys.exit(main())
