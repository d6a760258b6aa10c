"""``python -m brushcore.cli``: the ``brushcore`` command."""

import sys

from brushcore.cli import main

sys.exit(main())
