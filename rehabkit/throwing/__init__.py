"""Throwing: parametric underhand throws, retargeting, ballistics and a learned throw generator."""
