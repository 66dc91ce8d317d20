"""The serial protocol, pure and without I/O: ``codec`` (the host's commands and the
board's lines), ``can_frames`` (the same messages as CAN frames, protocol/CAN.md) and
``spec`` (protocol/spec.toml: every shared constant, and the firmware header
generated from it)."""
