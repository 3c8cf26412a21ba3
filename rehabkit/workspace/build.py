"""Building a workspace look-up table, once, cached on disk.

1. Bounding box: forward kinematics over a grid of joint values spanning every
   joint's range (plus random samples), padded by two voxels.
2. Voxels of ``resolution`` edge; each centroid is tested for reachability by
   the robot's own vectorised inverse kinematics, in chunks, on all cores.
3. Labels: reachable voxels whose 26 neighbours are all reachable are inner,
   the other reachable ones boundary.

The table is keyed by a hash of the robot's kinematics, limits, the IK
sampling and the resolution, and stored under ``$REHABKIT_CACHE`` (default
``~/.cache/rehabkit``) as ``workspace-<hash>.npz``. A robot plugin may ship the
table of its default kinematics beside its module (``shipped``: such a file,
its hash inside, e.g. L-Exos at 1 cm: 24 kB against ~5 s of building); it is
used only while the hash matches, so a changed robot builds its own.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from scipy import ndimage
from tqdm import tqdm

from rehabkit.workspace.grid import BOUNDARY, INNER, UNREACHABLE, VoxelWorkspace

FORMAT_VERSION = 1
CHUNK = 20_000
SERIAL_BELOW = 2_000_000  # voxels: fewer are labelled in this process (L-Exos: ~2 µs a voxel, compiled)


def cache_dir() -> Path:
    return Path(os.environ.get("REHABKIT_CACHE", Path.home() / ".cache" / "rehabkit"))


def bounding_box(fk_batch: Callable[[np.ndarray], np.ndarray], lower: np.ndarray, upper: np.ndarray,
                 per_joint: int = 25, random: int = 200_000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Min and max of the tip position over a joint grid plus random joint samples."""
    axes = [np.linspace(lo, hi, per_joint) for lo, hi in zip(lower, upper)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(lower))
    rand = np.random.default_rng(seed).uniform(lower, upper, (random, len(lower)))
    pts = np.concatenate([fk_batch(chunk)[:, :3, 3] for chunk in np.array_split(np.vstack([grid, rand]), 64)])
    return pts.min(axis=0), pts.max(axis=0)


def _label_chunk(args: tuple[Callable[[np.ndarray], np.ndarray], np.ndarray]) -> np.ndarray:
    reachable, points = args
    return reachable(points)


def build_workspace(
    key: str,
    fk_batch: Callable[[np.ndarray], np.ndarray],
    reachable: Callable[[np.ndarray], np.ndarray],
    lower: np.ndarray,
    upper: np.ndarray,
    resolution: float = 0.01,
    workers: int | None = None,
    progress: bool = True,
    use_cache: bool = True,
    shipped: Path | None = None,
    superset: VoxelWorkspace | None = None,
) -> VoxelWorkspace:
    """The look-up table for a robot, from the cache or built now.

    Args:
        key: Identifies the robot's kinematics and IK sampling (hashed with the resolution).
        fk_batch: (N, n) joint values → (N, 4, 4) tip poses.
        reachable: (N, 3) points → (N,) bool; must be picklable to run in worker processes.
        lower, upper: Joint ranges [rad].
        resolution: Voxel edge [m].
        workers: Processes (default: all cores).
        progress: Show a progress bar while building.
        use_cache: Read and write the on-disk cache.
        shipped: A table shipped with the robot: used if it was built for the same hash.
        superset: The table of the same robot with joint ranges containing ``lower``..``upper``: only its
            reachable voxels can be reachable with these, so only they are tested, on its grid.
    """
    digest = hashlib.sha256(f"{FORMAT_VERSION}|{key}|{resolution:.6g}".encode()).hexdigest()[:20]
    path = cache_dir() / f"workspace-{digest}.npz"
    if use_cache and path.exists():
        with np.load(path) as f:
            return VoxelWorkspace(f["origin"], float(f["resolution"]), f["labels"])
    if use_cache and shipped is not None and Path(shipped).exists():
        with np.load(shipped) as f:
            if str(f["digest"]) == digest:
                return VoxelWorkspace(f["origin"], float(f["resolution"]), f["labels"])

    if superset is not None and superset.resolution == resolution:
        origin, shape = superset.origin, superset.labels.shape
        candidates = superset.labels.ravel() >= BOUNDARY
        idx = np.indices(shape).reshape(3, -1).T[candidates]
    else:
        lo, hi = bounding_box(fk_batch, lower, upper)
        origin = np.floor(lo / resolution) * resolution - 2 * resolution
        shape = tuple(int(n) for n in np.ceil((hi - origin) / resolution).astype(int) + 3)
        candidates = slice(None)
        idx = np.indices(shape).reshape(3, -1).T
    centres = origin + idx * resolution
    chunks = [centres[i : i + CHUNK] for i in range(0, len(centres), CHUNK)]
    # worker processes pay for their start-up (~1.5 s here) only on large tables
    workers = workers or (os.cpu_count() or 1 if len(centres) > SERIAL_BELOW else 1)
    bar = tqdm(total=len(centres), unit="voxel", unit_scale=True, disable=not progress, desc="workspace",
               leave=False)
    results = []
    if workers > 1:
        with ProcessPoolExecutor(workers) as pool:
            for chunk, ok in zip(chunks, pool.map(_label_chunk, [(reachable, c) for c in chunks])):
                results.append(ok)
                bar.update(len(chunk))
    else:
        for chunk in chunks:
            results.append(reachable(chunk))
            bar.update(len(chunk))
    bar.close()
    reach = np.zeros(int(np.prod(shape)), bool)
    reach[candidates] = np.concatenate(results)
    reach = reach.reshape(shape)
    inner = ndimage.binary_erosion(reach, structure=np.ones((3, 3, 3), bool), border_value=0)
    labels = np.full(shape, UNREACHABLE, dtype=np.uint8)
    labels[reach] = BOUNDARY
    labels[inner] = INNER
    ws = VoxelWorkspace(origin, resolution, labels)
    if use_cache:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp.npz")
        np.savez_compressed(tmp, origin=origin, resolution=resolution, labels=labels, digest=digest)
        os.replace(tmp, path)
    return ws
