"""Locally weighted linear regression (Atkeson, Moore & Schaal), as the paper's throw generator uses."""

from __future__ import annotations

import numpy as np


class LWLR:
    """Predicts outputs for a query from a weighted linear fit of the nearby samples.

    Weights are Gaussian in the scaled input distance (``bandwidth`` in units of each
    input's spread); a small ridge keeps the local fit defined with few neighbours.
    """

    def __init__(self, inputs: np.ndarray, outputs: np.ndarray, bandwidth: float = 0.5, ridge: float = 1e-6):
        self.x = np.atleast_2d(np.asarray(inputs, float))
        self.y = np.atleast_2d(np.asarray(outputs, float))
        if len(self.x) != len(self.y):
            raise ValueError(f"{len(self.x)} inputs but {len(self.y)} outputs")
        self.scale = np.maximum(self.x.std(axis=0), 1e-12)
        self.bandwidth, self.ridge = bandwidth, ridge
        self._design = np.column_stack([np.ones(len(self.x)), (self.x - self.x.mean(axis=0)) / self.scale])
        self._centre = self.x.mean(axis=0)

    def predict(self, query: np.ndarray) -> np.ndarray:
        z = (np.asarray(query, float) - self._centre) / self.scale
        d2 = (((self.x - self._centre) / self.scale - z) ** 2).sum(axis=1)
        w = np.exp(-0.5 * d2 / self.bandwidth**2)
        X = self._design
        XtW = X.T * w
        beta = np.linalg.solve(XtW @ X + self.ridge * np.eye(X.shape[1]), XtW @ self.y)
        return np.concatenate([[1.0], z]) @ beta
