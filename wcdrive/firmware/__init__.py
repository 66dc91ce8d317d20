"""The bit-exact Python port of firmware/final_control/final_control.ino.

``final_control`` is the sketch's ``setup()`` and ``loop()`` (``Firmware``); beside it
one module per section of the sketch: ``commands``, ``control``, ``motion``,
``output``, ``quadrature``, ``params``, ``constants`` and ``state``. Function names are
the sketch's in snake case (``parseBounded`` is ``parse_bounded``).
"""
