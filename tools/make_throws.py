"""Generate the library of human underhand throwing demonstrations (run once; the output is committed).

    python tools/make_throws.py plugins/planners/throw_demos.npz

We have no motion capture, so the demonstrations are synthesised from the pendulum-like
wrist model of ``rehabkit.throwing.model`` at human scale: an arm of 0.68 m swung with the
elbow slightly bent (radius about 0.62 m), a gentle therapeutic toss released near the peak
of the swing at about 1.9 m/s. Trial-to-trial variability: each throw's back-swing and
release angles, phase durations, release angular speed, hand radius and aim are drawn from
normal distributions (seed fixed). Each record holds the parameters and the sampled wrist
path (200 Hz, shoulder frame, x forward, z up) from the start of the motion to the release,
as a capture system would.
"""

from __future__ import annotations

import sys

import numpy as np

from rehabkit.throwing.model import PARAMS, Throw, hand_path

N, RATE, SEED = 30, 200.0, 20180604
ARM_LENGTH = 0.68  # shoulder to palm of the demonstrator, arm straight [m]; the swing radius is shorter (elbow bent)
NOMINAL = {"back": -0.45, "release": 0.7, "t_back": 0.45, "t_fwd": 0.55, "omega": 3.0, "radius": 0.62, "aim": 0.0}
SPREAD = {"back": 0.10, "release": 0.12, "t_back": 0.05, "t_fwd": 0.04, "omega": 0.25, "radius": 0.02, "aim": 0.08}


def main(out: str) -> None:
    rng = np.random.default_rng(SEED)
    params, paths, times = [], [], []
    for _ in range(N):
        th = Throw(**{k: NOMINAL[k] + SPREAD[k] * rng.normal() for k in PARAMS})
        t = np.arange(0.0, th.release_time + 1e-9, 1.0 / RATE)
        p, _, _ = hand_path(th, np.zeros(3), t)
        params.append(th.vector())
        paths.append(p)
        times.append(t)
    length = max(len(t) for t in times)
    padded = np.full((N, length, 3), np.nan)  # ragged: NaN after each throw's release
    for i, p in enumerate(paths):
        padded[i, : len(p)] = p
    np.savez_compressed(out, params=np.array(params), param_names=np.array(PARAMS), wrist=padded, rate_hz=RATE,
                        arm_length_m=ARM_LENGTH, seed=SEED)
    print(f"wrote {out}: {N} throws, release speed {np.mean([p[4] * p[5] for p in params]):.2f} m/s on average")


if __name__ == "__main__":
    main(sys.argv[1])
