"""The MCAP run log: the sink and its messages (knows no solver)."""
