"""Finished runs as a Motion-BIDS dataset (``rehabkit export bids``), and each participant's progress across sessions
(``rehabkit progress``): a layer above the rehab layer and the sweeps, read from the run folders they leave."""
