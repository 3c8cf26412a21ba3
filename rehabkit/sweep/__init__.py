"""Sweeps and Monte Carlo studies: one scenario run many times (a grid of settings × seeds), on Ray."""
