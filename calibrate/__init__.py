"""Calibrate the friction model against measured data and name the effect it misses."""
