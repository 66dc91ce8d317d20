"""The toolchain as the sketch sees it (pure, no I/O): ``f32`` (binary32 arithmetic as
avr-gcc and avr-libc compute it, division included), ``avrlibc`` (``strtod``),
``arduino_print`` (``Print``'s number formatting), ``timer0`` (``millis()``, and
``F_CPU``, defined only there) and ``uart`` (cycles per received byte)."""
