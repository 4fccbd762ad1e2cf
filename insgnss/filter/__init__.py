"""Error-state Kalman filter, measurement models and RTS smoother."""
