"""Simulation: trajectories, sensor errors, GNSS/odometer/magnetometer synthesis, scenarios.

Flow: :func:`trajectory.generate` (truth) -> :func:`insgnss.mechanization.inverse.inverse_mechanize`
(ideal IMU) -> :func:`sensors.simulate_imu` (errors) and :mod:`aiding` (GNSS, odometer,
magnetometer); :func:`scenario.simulate_scenario` runs it all from a TOML scenario file.
See docs/simulation.md.
"""
