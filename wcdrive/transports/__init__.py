"""Ways to reach a board: the in-process simulated chair (``SimulatedBoard``) so far."""
