"""L-Exos kinematics, the workspace look-up table and the voxel searches."""

import numpy as np
import pytest

from rehabkit.workspace.grid import BOUNDARY, INNER, UNREACHABLE, VoxelWorkspace
from rehabkit.workspace.search import SearchFailedError, astar, beam, decimate, hill, path_length


@pytest.fixture(scope="module")
def lexos():
    from rehabkit_plugins.robots.lexos import LexosConfig, LexosRobot

    return LexosRobot(LexosConfig())


@pytest.fixture(scope="module")
def ws(lexos):
    return lexos.workspace(progress=False)  # the table shipped beside the plugin (built here: ~5 s)


def test_swivel_ik_reproduces_the_hand_position(lexos, rng):
    lim = lexos.model.limits
    q = rng.uniform(lim.lower, lim.upper, (300, 4))
    p = lexos.chain.fk_batch(q)[:, :3, 3]
    sols = lexos.position_ik(p)  # (300, swivel, 4)
    hands = lexos.chain.fk_batch(sols.reshape(-1, 4))[:, :3, 3].reshape(300, -1, 3)
    np.testing.assert_allclose(hands, np.broadcast_to(p[:, None, :], hands.shape), atol=1e-12)
    assert lexos.reachable(p).mean() > 0.99  # the rest: swivel windows narrower than the 3° sampling


def test_the_compiled_reachability_test_is_the_swivel_iks(lexos, rng):
    """The table's point test (compiled, stopping at the first swivel sample in range) says what the vectorised IK
    says, point for point, with the arm's ranges and with a patient's narrower ones."""
    from rehabkit_plugins.robots.lexos import SwivelReachability

    lim = lexos.model.limits
    p = rng.uniform(-0.7, 0.7, (20_000, 3))
    for lower, upper in ((lim.lower, lim.upper), (lim.lower + 0.3 * (lim.upper - lim.lower),
                                                  lim.upper - 0.2 * (lim.upper - lim.lower))):
        q = lexos.position_ik(p)
        with np.errstate(invalid="ignore"):
            expected = np.all((q >= lower) & (q <= upper), axis=-1).any(axis=1)
        assert 0.005 < expected.mean() < 0.5
        np.testing.assert_array_equal(SwivelReachability(*lexos.lengths, lower, upper, lexos.swivel)(p), expected)


def test_fk_batch_matches_pinocchio(lexos, rng):
    q = rng.uniform(-2, 2, (50, 4))
    batch = lexos.chain.fk_batch(q)
    for qi, t in zip(q, batch):
        np.testing.assert_allclose(t, lexos.model.ee_pose(qi), atol=1e-12)


def test_table_labels_are_consistent(ws, lexos, rng):
    lab = ws.labels
    assert lab.dtype == np.uint8 and set(np.unique(lab)) == {UNREACHABLE, BOUNDARY, INNER}
    # every table entry is the IK verdict at the voxel centre
    idx = np.argwhere(np.ones(lab.shape, bool))[rng.choice(lab.size, 3000, replace=False)]
    np.testing.assert_array_equal(lexos.reachable(ws.centre(idx)), lab[tuple(idx.T)] >= BOUNDARY)
    # boundary voxels touch unreachable space; inner ones don't
    for label, touches in ((BOUNDARY, True), (INNER, False)):
        sample = np.argwhere(lab == label)[:: max(1, (lab == label).sum() // 500)]
        for i, j, k in sample:
            assert (lab[i - 1 : i + 2, j - 1 : j + 2, k - 1 : k + 2] == UNREACHABLE).any() == touches


def test_a_table_is_built_from_the_ik_when_none_is_cached_or_shipped(tmp_path, monkeypatch, rng):
    """The build itself (the shipped 1 cm table spares it at 1 cm, coarser here): bounding box, labels from the IK in
    worker processes, erosion into inner and boundary, written to the cache and read back. Then a patient's ranges
    within the arm's own: a voxel out of reach with the wider ranges is out of reach with these, so only the own
    table's reachable voxels are tested; the verdicts are the IK's with the narrower ranges."""
    from rehabkit_plugins.robots.lexos import LexosConfig, LexosRobot

    monkeypatch.setenv("REHABKIT_CACHE", str(tmp_path))
    assert LexosRobot(LexosConfig()).workspace(progress=False).labels.size > 10**6  # the shipped table,
    assert not list(tmp_path.glob("*.npz"))  # read from beside the plugin, not built
    robot = LexosRobot(LexosConfig(swivel_samples=24))  # a coarser IK sampling: a table of its own, built here
    own = robot.workspace(resolution=0.04, progress=False)
    lab = own.labels
    idx = np.argwhere(np.ones(lab.shape, bool))
    np.testing.assert_array_equal(robot.reachable(own.centre(idx)), lab[tuple(idx.T)] >= BOUNDARY)
    assert set(np.unique(lab)) == {UNREACHABLE, BOUNDARY, INNER} and len(list(tmp_path.glob("workspace-*.npz"))) == 1
    np.testing.assert_array_equal(robot.workspace(resolution=0.04, progress=False).labels, lab)  # from the cache
    robot.model.limits = robot.model.limits.override(1, lower=np.radians(-20.0)).override(3, upper=np.radians(-30.0))
    narrow = robot.workspace(resolution=0.04, progress=False)
    assert narrow.labels.shape == lab.shape and np.all(narrow.labels[lab == UNREACHABLE] == UNREACHABLE)
    np.testing.assert_array_equal(robot.reachable(narrow.centre(idx)), narrow.labels[tuple(idx.T)] >= BOUNDARY)
    assert 0.2 < (narrow.labels >= BOUNDARY).sum() / (lab >= BOUNDARY).sum() < 0.95  # narrower, not empty


def test_workspace_is_concave(ws, rng):
    inner = ws.inner_points()
    pairs = inner[rng.integers(len(inner), size=(400, 2))]
    blocked = sum(not ws.segment_inner(a, b) for a, b in pairs)
    assert 40 < blocked < 360  # many straight lines leave it: concave, and not mostly empty


def test_segment_test_agrees_with_ik_sampling(ws, lexos, rng):
    inner = ws.inner_points()
    for a, b in inner[rng.integers(len(inner), size=(200, 2))]:
        if ws.segment_inner(a, b):
            pts = a + np.linspace(0, 1, 100)[:, None] * (b - a)
            assert lexos.reachable(pts).all()


def test_proxy_point_is_reachable_near_the_surface_in_seven_lookups(ws, rng):
    inner = ws.inner_points()
    for start in inner[rng.integers(len(inner), size=50)]:
        direction = rng.normal(size=3)
        target = start + 0.9 * direction / np.linalg.norm(direction)  # ≤ 1.28 m away
        if ws.reachable(target):
            continue
        proxy, used = ws.proxy_point(start, target, level=BOUNDARY)
        assert used <= 7
        assert ws.reachable(proxy)
        # the bisection's unreachable end lies within one voxel further along the line
        ahead = proxy + np.linspace(0, ws.resolution, 60)[1:, None] * (target - start) / np.linalg.norm(target - start)
        assert not all(ws.reachable(p) for p in ahead)


def _check_path(ws, path, a, b):
    assert np.all(ws.label(path) == INNER)
    np.testing.assert_allclose(path[0], ws.centre(ws.index(a[None]))[0])
    np.testing.assert_allclose(path[-1], ws.centre(ws.index(b[None]))[0])
    assert np.all(np.linalg.norm(np.diff(path, axis=0), axis=1) <= np.sqrt(3) * ws.resolution + 1e-9)


def test_searches_stay_inside_and_astar_is_shortest(ws, rng):
    inner = ws.inner_points()
    found = 0
    while found < 8:
        a, b = inner[rng.integers(len(inner), size=2)]
        if ws.segment_inner(a, b):
            continue
        found += 1
        best = astar(ws, a, b)
        _check_path(ws, best, a, b)
        for other in (astar(ws, a, b, weight=1.5), beam(ws, a, b), hill(ws, a, b)):
            _check_path(ws, other, a, b)
            assert path_length(best) <= path_length(other) + 1e-9


def _cup() -> VoxelWorkspace:
    # the start sits in a U-shaped pocket whose opening faces away from the goal
    lab = np.zeros((44, 44, 5), np.uint8)
    lab[2:42, 2:42, 1:4] = INNER
    lab[22, 8:36, 1:4] = UNREACHABLE  # bottom of the cup, between start and goal
    lab[6:23, 8, 1:4] = UNREACHABLE  # its two sides; the opening is at x < 6
    lab[6:23, 35, 1:4] = UNREACHABLE
    return VoxelWorkspace(np.zeros(3), 0.01, lab)


@pytest.mark.parametrize("greedy", [hill, beam])
def test_greedy_searches_report_failure_instead_of_looping(greedy):
    ws = _cup()
    start, goal = ws.centre(np.array([18, 21, 2])), ws.centre(np.array([32, 21, 2]))
    assert path_length(astar(ws, start, goal)) > 0.4  # out through the opening and round the cup
    with pytest.raises(SearchFailedError) as failed:
        greedy(ws, start, goal, max_steps=80)
    assert failed.value.kind in ("stuck", "no-arrival")


def test_search_refuses_endpoints_outside_the_inner_workspace(ws):
    with pytest.raises(SearchFailedError) as refused:
        astar(ws, np.array([5.0, 5.0, 5.0]), ws.inner_points()[0])
    assert refused.value.kind == "not-inner"


def test_decimation_keeps_ends():
    path = np.arange(10.0)[:, None] * np.ones(3)
    np.testing.assert_array_equal(decimate(path, 3)[[0, -1]], path[[0, -1]])
    np.testing.assert_array_equal(decimate(path, 3)[:, 0], [0, 3, 6, 9])


def test_q5_is_simulated_and_measured_but_not_driven(lexos):
    import mujoco

    assert lexos.model.passive_joints == ["q5_pronation"]
    assert lexos.model.pin_model.nq == 4  # locked in the control model
    mj = mujoco.MjModel.from_xml_string(lexos.model.mjcf)
    assert mj.njnt == 5 and mj.joint("q5_pronation").stiffness[0] > 0
    # turning q5 does not move the handle centre
    d = mujoco.MjData(mj)
    site = mj.site("handle").id
    positions = []
    for q5 in (-1.0, 0.0, 1.0):
        d.qpos[:] = [0.3, -0.8, 0.2, -1.0, q5]
        mujoco.mj_forward(mj, d)
        positions.append(d.site_xpos[site].copy())
    np.testing.assert_allclose(positions[0], positions[2], atol=1e-12)
    np.testing.assert_allclose(positions[1], lexos.fk([0.3, -0.8, 0.2, -1.0])[:3, 3], atol=1e-12)
