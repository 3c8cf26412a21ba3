"""A small policy stored as a file: a linear map or a multilayer perceptron (tanh), inputs normalised, outputs in
[−1, 1] — numpy inference, a few microseconds a call, the same in a learning environment, in a simulated run and
over a robot link.

The file (``.npz``) holds the layers, the input normalisation and what the policy was trained for (``meta``: the
observation terms, the action's kind and scale, the policy rate, the controller it acts on, the episode length).
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


@dataclass
class Policy:
    """``action = tanh(W_L … tanh(W_1 x̂ + b_1) … + b_L)``, ``x̂ = (x − mean) / std``."""

    layers: list[tuple[np.ndarray, np.ndarray]]
    mean: np.ndarray
    std: np.ndarray
    meta: dict = field(default_factory=dict)

    @classmethod
    def zeros(cls, sizes: list[int], mean: np.ndarray | None = None, std: np.ndarray | None = None,
              meta: dict | None = None) -> Policy:
        """A policy of layer ``sizes`` (inputs, hidden…, outputs) whose action is zero everywhere."""
        layers = [(np.zeros((b, a)), np.zeros(b)) for a, b in zip(sizes[:-1], sizes[1:])]
        n = sizes[0]
        return cls(layers, np.zeros(n) if mean is None else mean, np.ones(n) if std is None else std, meta or {})

    @property
    def sizes(self) -> list[int]:
        return [self.layers[0][0].shape[1], *(W.shape[0] for W, _ in self.layers)]

    def __call__(self, x: np.ndarray) -> np.ndarray:
        h = (np.asarray(x, float) - self.mean) / self.std
        for W, b in self.layers:
            h = np.tanh(W @ h + b)
        return h

    # -- as one vector (what a black-box optimiser searches) -----------------------------------------------

    def flat(self) -> np.ndarray:
        return np.concatenate([np.concatenate([W.ravel(), b]) for W, b in self.layers])

    def with_flat(self, theta: np.ndarray) -> Policy:
        layers, at = [], 0
        for W, b in self.layers:
            w = theta[at : at + W.size].reshape(W.shape)
            at += W.size
            layers.append((w, theta[at : at + b.size].copy()))
            at += b.size
        if at != len(theta):
            raise ValueError(f"{len(theta)} parameters for a policy of {at}")
        return Policy(layers, self.mean, self.std, self.meta)

    # -- the file ------------------------------------------------------------------------------------------

    def save(self, path: str | Path) -> Path:
        """Written whole (a temporary file, then renamed)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        arrays = {"mean": self.mean, "std": self.std, "meta": np.array(json.dumps(self.meta))}
        for i, (W, b) in enumerate(self.layers):
            arrays[f"W{i}"], arrays[f"b{i}"] = W, b
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".npz")
        umask = os.umask(0)
        os.umask(umask)
        os.fchmod(fd, 0o666 & ~umask)  # mkstemp makes it private; a policy file is an ordinary output
        os.close(fd)
        np.savez(tmp, **arrays)
        os.replace(tmp, path)
        return path

    @classmethod
    def load(cls, path: str | Path) -> Policy:
        with np.load(path, allow_pickle=False) as f:
            n = sum(1 for k in f.files if k.startswith("W"))
            if n == 0 or "mean" not in f.files:
                raise ValueError(f"{path} is not a policy file (no layers W0, b0, … and mean/std)")
            layers = [(f[f"W{i}"].astype(float), f[f"b{i}"].astype(float)) for i in range(n)]
            meta = json.loads(str(f["meta"])) if "meta" in f.files else {}
            return cls(layers, f["mean"].astype(float), f["std"].astype(float), meta)
