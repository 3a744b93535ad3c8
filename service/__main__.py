"""``python -m quadloc.service`` = the ``quadloc`` command."""

import sys

from quadloc.service.cli.main import main

sys.exit(main())
