"""The verification harness, shipped as ``wcdrive.hil``: ``traces`` (random input
traces), ``lockstep`` (the port against the compiled firmware in simavr, event by
event), ``verify`` (``wcdrive verify``) and ``fpcheck`` (single binary32 and
formatting operations on the AVR). It imports only the library; nothing in the library
below the tools imports it."""
