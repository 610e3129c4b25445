"""Model calibration: linear (damping equalization) and nonlinear (multi-harmonic FRFs)."""
