"""The occupancy grid Ψ and the joint matrix Θ, cached on disk by their content."""

from __future__ import annotations

import numpy as np

from rehabkit.cspace import cache
from rehabkit.cspace.cache import cached_array, key_of


def test_a_grid_is_built_once_per_content_and_rebuilt_when_anything_differs(tmp_path, monkeypatch):
    monkeypatch.setenv("REHABKIT_CACHE", str(tmp_path))
    monkeypatch.setattr(cache, "_MEMO", {})
    builds = []

    def build():
        builds.append(1)
        return np.arange(12, dtype=float).reshape(3, 4)

    key = key_of("theta-v1", np.ones(3), 0.5)
    first = cached_array("theta", key, build)
    monkeypatch.setattr(cache, "_MEMO", {})  # a new process: from the disk this time
    again = cached_array("theta", key, build)
    assert len(builds) == 1 and np.array_equal(first, again) and list(tmp_path.glob("theta-*.npy"))
    cached_array("theta", key_of("theta-v1", np.ones(3), 0.25), build)  # another resolution: built
    assert len(builds) == 2
    assert key_of(np.zeros(3)) != key_of(np.zeros(3, np.float32))  # exact contents, dtype included


def test_an_unreadable_cache_file_is_rebuilt_not_trusted(tmp_path, monkeypatch):
    monkeypatch.setenv("REHABKIT_CACHE", str(tmp_path))
    monkeypatch.setattr(cache, "_MEMO", {})
    key = key_of("psi-v1", 3)
    cached_array("psi", key, lambda: np.zeros((2, 2), bool))
    (path,) = tmp_path.glob("psi-*.npy")
    path.write_bytes(b"not an array")
    monkeypatch.setattr(cache, "_MEMO", {})
    assert cached_array("psi", key, lambda: np.ones((2, 2), bool)).all()
