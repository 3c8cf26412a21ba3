"""HIT analytic IK (reverse coordinate method) against FK and Pinocchio."""

import numpy as np
import pytest
from rehabkit_plugins.robots.hit import fk, ik, ik_inverted, mdh_rows

from rehabkit.models.chain import inv_se3, mdh_transform

A_DEG = [0, 90, 90, 30, -90, 90]
B_POS = [-0.45, -0.1, -0.3]


def _wrapdiff(a, b):
    return (np.asarray(a) - b + np.pi) % (2 * np.pi) - np.pi


def test_original_pose_is_inverse_of_inverted_chain(rng):
    for _ in range(100):
        q = rng.uniform(-np.pi, np.pi, 6)
        theta = -q[::-1]  # Θi = −θ(7−i)
        t = np.eye(4)
        for row, th in zip(mdh_rows(), theta):
            t = t @ mdh_transform(row, th)
        np.testing.assert_allclose(fk(q), inv_se3(t), atol=1e-12)


def test_the_robots_batch_kinematics_is_the_papers_fk(hit, rng):
    qs = rng.uniform(-np.pi, np.pi, (2000, 6))
    np.testing.assert_allclose(hit.fk_batch(qs), np.stack([fk(q) for q in qs]), atol=1e-12)


def test_ik_round_trip_over_thousands_of_random_poses(hit, rng):
    qs = rng.uniform(-np.pi, np.pi, (3000, 6))
    targets = hit.fk_batch(qs)  # the paper's fk, vectorised (the test above)
    sols, owner, counts = [], [], []
    for i, (q, target) in enumerate(zip(qs, targets)):
        found = ik(target)
        counts.append(len(found))
        assert min(np.abs(_wrapdiff(s, q)).max() for s in found) < 1e-6  # the original posture is among them
        sols += found
        owner += [i] * len(found)
    worst = np.abs(hit.fk_batch(np.array(sols)) - targets[owner]).max()  # every solution reaches its pose
    assert worst < 1e-10
    assert np.median(counts) == 8  # generic poses: 2 (θ1) × 2 (θ3) × 2 (wrist flip)


def test_ik_on_the_papers_point_b():
    A = fk(np.radians(A_DEG))
    B = A.copy()
    B[:3, 3] = B_POS
    sols = ik(B)
    assert len(sols) == 8
    for s in sols:
        np.testing.assert_allclose(fk(s), B, atol=1e-12)


def test_ik_every_branch_of_the_inverted_chain_is_distinct():
    A = fk(np.radians(A_DEG))
    thetas = ik_inverted(inv_se3(A))
    assert len(thetas) == 8
    assert len({tuple(np.round(np.mod(t, 2 * np.pi), 6)) for t in thetas}) == 4  # A sits at s5 = ±1: pairs coincide


def test_unreachable_pose_has_no_solution():
    T = np.eye(4)
    T[:3, 3] = [1.0, 0.0, 0.0]  # beyond l1 + l2 + l3
    assert ik(T) == []


@pytest.mark.parametrize("q_deg", [[10, 20, 30, 0.0, 50, 60], [0, 0, 0, 0, 0, 0], [30, 90, -20, 45, 0, -30]])
def test_singular_configurations_still_round_trip(q_deg):
    target = fk(np.radians(q_deg))
    sols = ik(target)
    assert sols, "a reachable singular pose must have at least one solution"
    for s in sols:  # √(1 − k1²) near the straight elbow costs precision: 1e-6, not 1e-12
        np.testing.assert_allclose(fk(s), target, atol=1e-6)
