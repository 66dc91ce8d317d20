"""The tools: the wcdrive CLI, the bench, replay, sweeps, the console's logging."""
