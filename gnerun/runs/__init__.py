"""Drivers: solve, closed loop, sweeps and run directories (solvers + the log sink)."""
