"""Generated robots: MuJoCo and Pinocchio must be the same robot."""

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from rehabkit.models.mjcf_builder import link_inertia


def _compare(model, rng, n=20):
    mj = mujoco.MjModel.from_xml_string(model.mjcf)
    d = mujoco.MjData(mj)
    pm, pd = model.pin_model, model.pin_model.createData()
    site = mj.site(model.ee_site).id
    for _ in range(n):
        q = rng.uniform(model.limits.lower, model.limits.upper)
        v, a = rng.normal(size=model.dof), rng.normal(size=model.dof)
        d.qpos[:], d.qvel[:] = q, v
        mujoco.mj_forward(mj, d)
        d.qacc[:] = a  # after mj_forward, which computes its own
        M = np.zeros((model.dof, model.dof))
        mujoco.mj_fullM(mj, d, M)
        np.testing.assert_allclose(pin.crba(pm, pd, q), M, atol=1e-10)
        mujoco.mj_inverse(mj, d)
        # MuJoCo's inverse dynamics includes viscous joint damping, a passive force RNEA leaves out
        np.testing.assert_allclose(pin.rnea(pm, pd, q, v, a) + mj.dof_damping * v, d.qfrc_inverse, atol=1e-9)
        np.testing.assert_allclose(model.ee_pose(q)[:3, 3], d.site_xpos[site], atol=1e-12)


def test_hit_mujoco_and_pinocchio_agree(hit, rng):
    _compare(hit.model, rng)


def test_hit_analytic_fk_matches_pinocchio_fk(hit, rng):
    for _ in range(200):
        q = rng.uniform(-np.pi, np.pi, 6)
        np.testing.assert_allclose(hit.fk(q), hit.model.ee_pose(q), atol=1e-12)


def test_link_inertia_of_a_rod_is_textbook():
    m, L, r = 2.0, 0.5, 0.01
    com, moments, _ = link_inertia([np.zeros(3), np.array([L, 0, 0])], m, r)
    np.testing.assert_allclose(com, [L / 2, 0, 0])
    np.testing.assert_allclose(sorted(moments), sorted([m * r * r / 2, m * (3 * r * r + L * L) / 12,
                                                        m * (3 * r * r + L * L) / 12]), rtol=1e-12)


def test_link_inertia_of_an_l_shape_uses_parallel_axes():
    # two equal rods meeting at a right angle; about the COM, I_zz = 2·(mL²/12 + m d²) with d = L/(2√2)
    m, L = 1.0, 0.4
    com, moments, _ = link_inertia([np.zeros(3), np.array([0, 0, L]), np.array([L, 0, L])], 2 * m, 1e-6)
    np.testing.assert_allclose(com, [L / 4, 0, 3 * L / 4], atol=1e-12)
    assert max(moments) == pytest.approx(2 * (m * L * L / 12 + m * (L * L / 8)), rel=1e-6)


def test_gravity_is_rotated_into_a_tilted_base(hit, rng):
    # with the HIT base yawed 180° about z, gravity in the base frame is still -z
    np.testing.assert_allclose(hit.model.pin_model.gravity.linear, [0, 0, -9.81], atol=1e-12)
