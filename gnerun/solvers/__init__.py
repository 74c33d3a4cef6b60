"""The Newton methods and the equilibrium certificate (numpy in, numpy out; no I/O)."""
