"""Box-avoid planner and the exact segment tests it is checked with."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rehabkit.geometry.box_avoid import NoPathError, plan_path
from rehabkit.geometry.solids import Box, Cylinder, Sphere, path_hits


def test_segment_tests_are_exact_at_the_surface():
    box = Box([0, 0, 0], [0.1, 0.2, 0.3])
    assert box.hits_segment([-1, 0.2, 0], [1, 0.2, 0])  # grazes the y face: closed solid
    assert not box.hits_segment([-1, 0.2 + 1e-9, 0], [1, 0.2 + 1e-9, 0])
    assert not box.hits_segment([0.5, 0, 0], [1, 0, 0])  # segment ends before the box
    sphere = Sphere([0, 0, 0], 0.5)
    assert sphere.hits_segment([-1, 0.5, 0], [1, 0.5, 0])
    assert not sphere.hits_segment([-1, 0.5001, 0], [1, 0.5001, 0])
    cyl = Cylinder([0, 0, 0], [0, 0, 1], 0.1, 0.2)
    assert cyl.hits_segment([-1, 0, 0.2], [1, 0, 0.2])  # across the cap rim
    assert not cyl.hits_segment([-1, 0, 0.2001], [1, 0, 0.2001])
    assert not cyl.hits_segment([0.0708, 0.0708, -1], [0.0708, 0.0708, 1])  # r = 0.10013 > 0.1
    assert cyl.hits_segment([0.07, 0.07, -1], [0.07, 0.07, 1])


def test_path_over_a_box_follows_its_faces():
    h = 0.1 + 0.005  # half size + clearance
    res = plan_path([-0.5, 0, 0], [0.5, 0, 0], [Box([0, 0, 0], [0.1, 0.1, 0.1])])
    # straight to the entry face, out to an edge, across the adjacent face, down the exit face
    assert res.length == pytest.approx(1 + 2 * h, abs=1e-9)
    assert len(res.path) == 6
    assert not path_hits(res.path, Box([0, 0, 0], [0.1, 0.1, 0.1]))


def test_clear_segment_is_returned_straight():
    res = plan_path([-0.5, 0.5, 0], [0.5, 0.5, 0], [Box([0, 0, 0], [0.1, 0.1, 0.1])])
    assert len(res.path) == 2


def test_margin_keeps_the_gripper_off_the_obstacle():
    box = Box([0, 0, 0], [0.1, 0.1, 0.1], Rotation.from_euler("xyz", [0.3, -0.2, 0.9]).as_matrix())
    res = plan_path([-0.5, 0.02, 0.01], [0.5, -0.03, 0.0], [box], margin=0.06)
    assert not path_hits(res.path, box.inflated(0.06))
    assert path_hits(np.array([[-0.5, 0.02, 0.01], [0.5, -0.03, 0.0]]), box)


def test_start_inside_an_obstacle_is_an_explicit_failure():
    with pytest.raises(NoPathError) as err:
        plan_path([0, 0, 0], [1, 0, 0], [Box([0, 0, 0], [0.2, 0.2, 0.2], name="tray")], margin=0.0)
    assert (err.value.end, err.value.obstacle) == ("start", "tray")


def test_start_in_the_clearance_shell_or_a_bounding_box_corner_still_plans():
    box = Box([0, 0, 0], [0.1, 0.1, 0.1])
    res = plan_path([-0.102, 0.0, 0.0], [0.5, 0.0, 0.0], [box])  # 2 mm off the face, clearance is 5 mm
    assert not path_hits(res.path, box)
    sphere = Sphere([0, 0, 0], 0.1)
    corner = np.array([0.075, 0.075, 0.0])  # outside the sphere (r = 0.106) but inside its box
    res = plan_path(corner, [-0.5, -0.1, 0.0], [sphere])
    assert not path_hits(res.path, sphere) and np.allclose(res.path[0], corner)


def _random_obstacles(rng, n):
    out = []
    for k in range(n):
        c = rng.uniform(-0.4, 0.4, 3)
        if k % 4 == 2:
            out.append(Sphere(c, rng.uniform(0.03, 0.12), f"s{k}"))
        elif k % 4 == 3:
            out.append(Cylinder(c, rng.normal(size=3), rng.uniform(0.03, 0.1), rng.uniform(0.03, 0.15), f"c{k}"))
        else:
            out.append(Box(c, rng.uniform(0.02, 0.15, 3), Rotation.random(random_state=rng).as_matrix(), f"b{k}"))
    return out


def _free(rng, obstacles, margin):
    while True:
        p = rng.uniform(-0.6, 0.6, 3)
        if not any(o.inflated(margin).contains(p) for o in obstacles):
            return p


def test_crowded_overlapping_environments_never_yield_a_colliding_path():
    """Dense scenes (obstacles overlap often): every returned path is checked against the true solids."""
    rng = np.random.default_rng(11)
    returned = failed = merged = 0
    for _ in range(300):
        obs = _random_obstacles(rng, 10)
        s, g = _free(rng, obs, 0.03), _free(rng, obs, 0.03)
        try:
            res = plan_path(s, g, obs, margin=0.03)
        except NoPathError:
            failed += 1
            continue
        returned += 1
        merged += res.merges > 0
        assert np.allclose(res.path[0], s) and np.allclose(res.path[-1], g)
        assert not any(path_hits(res.path, o.inflated(0.03)) for o in obs)
    assert merged > 0  # the overlap handling was exercised
    # measured: 0 of 300 (7 before starts/goals could step out of a merged hull between its members)
    assert failed <= 3
    assert returned + failed == 300


def test_a_cup_on_a_tray_start_between_them_and_never_under_the_floor():
    """Stacked obstacles (a cup standing on a tray that reaches the floor): their inflated boxes overlap and
    merge; a start beside the cup, inside the merged box, steps out upward, and no detour goes under the tray."""
    tray = Box([0.42, 0.0, 0.375], [0.14, 0.26, 0.375], name="tray")
    cup = Cylinder([0.45, -0.12, 0.80], [0, 0, 1], 0.04, 0.05, name="cup")
    floor = (np.array([0.0, 0.0, 1.0]), 0.07)
    start, goal = np.array([0.42, 0.05, 0.87]), np.array([0.40, -0.70, 0.50])
    res = plan_path(start, goal, [tray, cup], margin=0.07, floor=floor)
    assert res.merges >= 1
    assert not path_hits(res.path, tray.inflated(0.07)) and not path_hits(res.path, cup.inflated(0.07))
    assert res.path[:, 2].min() >= 0.07 - 1e-12
    assert res.path[1, 2] > start[2] and np.allclose(res.path[1, :2], start[:2])  # first step: straight up
    with pytest.raises(NoPathError) as below:
        plan_path(np.array([1.0, 1.0, 0.02]), goal, [tray], margin=0.07, floor=floor)
    assert (below.value.end, below.value.obstacle) == ("start", None)  # (no obstacle: below the floor)


def test_no_obstacles_gives_the_straight_segment():
    res = plan_path(np.zeros(3), np.ones(3), [])
    assert len(res.path) == 2 and res.length == pytest.approx(np.sqrt(3))
