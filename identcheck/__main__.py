"""``python -m identcheck``: the same command line as the ``identcheck`` script."""
import sys

from identcheck.cli import main

sys.exit(main())
