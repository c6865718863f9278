"""``python -m identcheck``: the same command line as the ``identcheck`` script.

Guarded: the worker processes of ``identcheck batch``'s local cluster are spawned, and a spawned process imports
the parent's ``__main__`` module again (as ``__mp_main__``), which must not run the command a second time."""
import sys

from identcheck.cli import main

if __name__ == "__main__":
    sys.exit(main())
