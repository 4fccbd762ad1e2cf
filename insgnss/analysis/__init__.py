"""Sensor analysis (Allan variance)."""
