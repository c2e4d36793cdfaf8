"""Simulated scans: scenes (built-in or YAML), ray casting with a sensor model, trajectories."""
