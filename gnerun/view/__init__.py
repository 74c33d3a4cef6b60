"""Figures and Rerun replays, from run logs only."""
