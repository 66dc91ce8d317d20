"""Everything that is a board: the threaded base, the port and the plant at the Mega's
timing (``port_loop``, ``sim_board``) and the compiled firmware in simavr (``simavr``)."""
