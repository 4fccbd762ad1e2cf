"""Simulation: trajectories, sensor errors, GNSS/odometer/magnetometer synthesis, scenarios."""
