"""``python -m wcdrive``: the same as the ``wcdrive`` command."""

import sys

from wcdrive.tools.cli import main

sys.exit(main())
