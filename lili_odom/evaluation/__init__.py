"""Trajectory metrics (via evo) and plots for offline runs and benchmarks."""
