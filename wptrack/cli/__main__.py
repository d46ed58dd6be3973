"""``python -m wptrack.cli``: the ``wptrack`` command."""

import sys

from wptrack.cli import main

sys.exit(main())
