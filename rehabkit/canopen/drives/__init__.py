"""The master's work on each drive: what it is told (limits, units, PDOs) at a run's start, what is checked before it
is enabled, and how it is left at the end."""
