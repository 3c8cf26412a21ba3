"""CaPaMan: kinematics against each other and against MuJoCo's constrained simulation."""

import mujoco
import numpy as np
import pytest
from rehabkit_plugins.robots.capaman import CapamanConfig, CapamanRobot
from rehabkit_plugins.robots.capaman_kinematics import forward, inverse


@pytest.fixture(scope="module")
def capaman():
    return CapamanRobot(CapamanConfig())


def _assembled(robot, q):
    m = mujoco.MjModel.from_xml_string(robot.model.mjcf)
    d = mujoco.MjData(m)
    values = {f"alpha_{k + 1}": np.array([q[k]]) for k in range(3)} | robot.passive_state(q)
    for name, v in values.items():
        adr = m.jnt_qposadr[m.joint(name).id]
        d.qpos[adr : adr + len(np.atleast_1d(v))] = v
    mujoco.mj_forward(m, d)
    return m, d


def _loop_gaps(d):
    pairs = [(f"coupler_end_{k}", f"follower_tip_{k}") for k in (1, 2, 3)] + \
        [(f"slider_{k}", f"plate_joint_{k}") for k in (2, 3)]
    return max(np.linalg.norm(d.site(a).xpos - d.site(b).xpos) for a, b in pairs)


def test_inverse_and_forward_kinematics_agree(capaman, rng):
    lim = capaman.model.limits
    alpha = rng.uniform(lim.lower, lim.upper, (3000, 3))
    p, R, residual = forward(capaman.geo, alpha)
    assert residual.max() < 1e-12
    back, _, consistency = inverse(capaman.geo, p, R)
    np.testing.assert_allclose(back, alpha, atol=1e-12)
    assert np.abs(consistency).max() < 1e-12
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)


def test_tool_position_ik_round_trip(capaman, rng):
    lim = capaman.model.limits
    for q in rng.uniform(lim.lower + 0.1, lim.upper - 0.1, (20, 3)):
        sols = capaman.ik(capaman.fk(q))
        assert sols, np.degrees(q)
        for sol in sols:  # every solution puts the tool where asked
            np.testing.assert_allclose(capaman.fk(sol)[:3, 3], capaman.fk(q)[:3, 3], atol=1e-9)
        assert min(np.abs(sol - q).max() for sol in sols) < 1e-6


def test_mujoco_closes_every_loop_where_the_kinematics_say(capaman, rng):
    lim = capaman.model.limits
    for q in rng.uniform(lim.lower, lim.upper, (10, 3)):
        m, d = _assembled(capaman, q)
        assert _loop_gaps(d) < 2e-6  # the MJCF writer keeps 6 significant digits
        np.testing.assert_allclose(d.site("tool_tip").xpos, capaman.fk(q)[:3, 3], atol=2e-6)


def test_constrained_simulation_follows_the_kinematics_in_motion(run_scenario, tmp_path):
    scenario = tmp_path / "capa.yaml"
    scenario.write_text("""\
robot: {type: capaman}
planner: {type: multi-cubic, segment_durations: [1.0, 1.0, 1.0]}
controller: {type: joint-pd, kp: 40, kd: 1.5, feedforward: gravity}
task:
  targets:
    - {name: home, joints_deg: [90, 90, 90]}
    - {name: p1, joints_deg: [60, 100, 120]}
    - {name: p2, joints_deg: [130, 50, 80]}
    - {name: p3, same_as: home}
duration: 3.5
expect: {tracking_max_deg: {lt: 1.0}, final_position_error_m: {lt: 0.001}, safety_events: {eq: 0}}
""")
    from rehabkit.core.run.runner import Runner
    from rehabkit.core.scenario.loader import load_scenario

    runner = Runner(load_scenario(scenario))
    result = runner.run()
    assert result.passed, result.failures
    b, robot = runner.backend, runner.robot
    _, q, _ = b.state()
    base = robot.model.base_pose
    tip_world = base[:3, :3] @ robot.fk(q)[:3, 3] + base[:3, 3]
    np.testing.assert_allclose(b.data.site("tool_tip").xpos, tip_world, atol=5e-4)  # constraints are soft
    assert _loop_gaps(b.data) < 5e-4


def test_gravity_model_holds_the_mechanism_still(capaman):
    from rehabkit.core.kinds.interfaces import Context
    from rehabkit.core.scenario.models import World
    from rehabkit.sim.mujoco import MujocoBackend, MujocoConfig

    ctx = Context(None, np.random.default_rng(0), 0.001, robot=capaman, world=World(floor=False))
    b = MujocoBackend(MujocoConfig(), ctx)
    q0 = np.radians([60.0, 100.0, 120.0])
    drift = {}
    for mode in ("model", "none"):
        b.reset(q0)
        b.set_joints(capaman.passive_state(q0))
        tau = capaman.gravity_torque(q0) if mode == "model" else np.zeros(3)
        for _ in range(300):
            b.command(tau)
            b.step()
        drift[mode] = np.degrees(np.abs(b.state()[1] - q0).max())
    assert drift["model"] < 0.05 and drift["none"] > 5.0
