"""Simulated-patient plugins."""
