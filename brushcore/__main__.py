"""``python -m brushcore``: the command line of `brushcore.cli`, as the
installed ``brushcore`` command runs it."""

import sys

from brushcore.cli import main

sys.exit(main())
