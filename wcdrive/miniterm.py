"""``python -m wcdrive.miniterm wcsim://``: pyserial's miniterm with wcdrive's URL
handlers registered (plain ``python -m serial.tools.miniterm`` does not import wcdrive)."""

import sys

from serial.tools.miniterm import main

import wcdrive  # noqa: F401  (registers wcsim://)

if __name__ == "__main__":
    sys.exit(main())
