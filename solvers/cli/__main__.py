"""``python -m solvers.cli``: the same as the ``tdoa-workbench`` command."""
import sys

from solvers.cli.app import main

sys.exit(main())
