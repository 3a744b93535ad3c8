"""``python -m service`` = the ``quadloc`` command."""

import sys

from service.cli import main

sys.exit(main())
