import numpy as np
import pytest

from rehabkit.models.chain import (
    DHRow,
    KinematicChain,
    inv_se3,
    matrix_to_quat_wxyz,
    mdh_transform,
    rpy_to_matrix,
    sdh_transform,
)

ROWS = [DHRow(0.1, 0.3, 0.2, 0.1), DHRow(-0.2, -1.2, 0.05), DHRow(0.0, 1.5708, 0.3, -0.4), DHRow(0.15, 0.0, 0.0)]


@pytest.mark.parametrize("convention, transform", [("modified", mdh_transform), ("standard", sdh_transform)])
def test_chain_fk_equals_product_of_dh_matrices(convention, transform, rng):
    chain = KinematicChain.from_dh(ROWS, convention)
    for _ in range(50):
        q = rng.uniform(-np.pi, np.pi, len(ROWS))
        expected = np.eye(4)
        for row, qi in zip(ROWS, q):
            expected = expected @ transform(row, qi)
        np.testing.assert_allclose(chain.fk(q), expected, atol=1e-12)


def test_prismatic_joint_moves_along_z():
    chain = KinematicChain.from_dh([DHRow(0, 0, 0.1, joint="prismatic")], "standard")
    np.testing.assert_allclose(chain.fk([0.25])[:3, 3], [0, 0, 0.35], atol=1e-12)


def test_reversed_chain_is_the_inverse_with_negated_reversed_joints(rng):
    chain = KinematicChain.from_dh(ROWS, "modified")
    rev = chain.reversed()
    for _ in range(50):
        q = rng.uniform(-np.pi, np.pi, len(ROWS))
        np.testing.assert_allclose(rev.fk(-q[::-1]), inv_se3(chain.fk(q)), atol=1e-12)


def test_quaternion_round_trip(rng):
    for _ in range(200):
        r = rpy_to_matrix(rng.uniform(-np.pi, np.pi, 3))
        w, x, y, z = matrix_to_quat_wxyz(r)
        back = np.array([
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ])
        np.testing.assert_allclose(back, r, atol=1e-12)
