"""The simulated Mega: the compiled firmware in simavr through a C harness and ctypes,
with the plant wired to its pins."""
