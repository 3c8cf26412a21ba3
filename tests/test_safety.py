"""The safety layer on its own: every rule, and what the robot gets after a trip."""

import numpy as np
import pinocchio as pin
import pytest

from rehabkit.core.safety.layer import SafetyLayer
from rehabkit.core.scenario.safety import SafetyConfig
from tests.conftest import checked


@pytest.fixture
def layer(hit):
    return SafetyLayer(hit.model, SafetyConfig(), gravity=hit.gravity_torque)


def _q_mid(hit):
    lim = hit.model.limits
    return (lim.lower + lim.upper) / 2


def test_safe_command_passes_unchanged(layer, hit):
    q, tau = _q_mid(hit), np.array([1.0, -2.0, 0.5, 0.1, 0.2, -0.3])
    out = checked(layer, 0.0, q, np.zeros(6), tau)
    np.testing.assert_array_equal(out, tau)
    assert not layer.tripped and not layer.events


@pytest.mark.parametrize("where", ["tau", "q", "qd"])
def test_nan_anywhere_trips_and_holds(layer, hit, where):
    q, qd, tau = _q_mid(hit), np.zeros(6), np.zeros(6)
    {"tau": tau, "q": q, "qd": qd}[where][2] = np.nan
    out = checked(layer, 0.1, q, qd, tau)
    assert layer.tripped and layer.events[0].rule == "non-finite"
    assert np.all(np.isfinite(out)) and np.all(np.abs(out) <= hit.model.limits.effort)
    assert layer.events[0].data["category"] == 2  # a controlled stop, then held (its wording: test_message_wording)


def test_position_breach_names_the_joint_and_limit(layer, hit):
    q = _q_mid(hit)
    q[3] = hit.model.limits.upper[3] + np.radians(1.0)  # beyond the 0.5° margin
    checked(layer, 2.0, q, np.zeros(6), np.zeros(6))
    ev = layer.events[0]
    assert ev.rule == "position" and ev.joint == "elbow_2" and ev.t == 2.0
    assert ev.limit == pytest.approx(hit.model.limits.upper[3] + np.radians(0.5))


def test_small_excursion_inside_the_margin_is_tolerated(layer, hit):
    q = _q_mid(hit)
    q[3] = hit.model.limits.upper[3] + np.radians(0.3)
    checked(layer, 0.0, q, np.zeros(6), np.zeros(6))
    assert not layer.tripped


def test_velocity_breach(layer, hit):
    qd = np.zeros(6)
    qd[4] = -1.2 * hit.model.limits.velocity[4]
    checked(layer, 0.0, _q_mid(hit), qd, np.zeros(6))
    assert layer.events[0].rule == "velocity" and layer.events[0].joint == "wrist_1"


def test_torque_is_clipped_by_default_and_trips_on_request(hit):
    eff = hit.model.limits.effort
    clip = SafetyLayer(hit.model, SafetyConfig())
    out = checked(clip, 0.0, _q_mid(hit), np.zeros(6), 3 * eff)
    np.testing.assert_allclose(out, eff)
    assert not clip.tripped and clip.saturated_steps == 1
    stop = SafetyLayer(hit.model, SafetyConfig(torque_policy="stop"))
    checked(stop, 0.0, _q_mid(hit), np.zeros(6), 3 * eff)
    assert stop.tripped and stop.events[0].rule == "torque"


def test_trip_is_latched_and_hold_pulls_back_to_the_trip_posture(layer, hit):
    q0 = _q_mid(hit)
    layer.trip(1.0, q0, "plan", "test")
    q = q0 + 0.05
    out = checked(layer, 1.1, q, np.zeros(6), np.full(6, 5.0))  # the controller's wish is ignored
    g = pin.rnea(hit.model.pin_model, hit.model.pin_model.createData(), q, np.zeros(6), np.zeros(6))
    np.testing.assert_allclose(out, np.clip(-60.0 * 0.05 + g, -hit.model.limits.effort, hit.model.limits.effort))


def test_zero_torque_robots_go_limp(hit):
    from dataclasses import replace

    limp = SafetyLayer(replace(hit.model, safe_stop="zero-torque"), SafetyConfig())
    limp.trip(0.0, _q_mid(hit), "plan", "test")
    np.testing.assert_array_equal(checked(limp, 0.0, _q_mid(hit), np.zeros(6), np.ones(6)), np.zeros(6))


def test_a_limit_the_stop_does_not_hold_is_said_once_while_it_goes_on(hit):
    """Tripped by another rule (here the e-stop), the layer still watches the state: a joint past its speed limit
    while the robot is being stopped is noted once (rule, joint, value, limit), and the stop goes on."""
    layer = SafetyLayer(hit.model, SafetyConfig(), gravity=hit.gravity_torque)
    q, qd = _q_mid(hit), np.zeros(6)
    layer.trip(1.0, q, "e-stop", "e-stop pressed", qd)
    fast = np.zeros(6)
    fast[4] = 1.2 * hit.model.limits.velocity[4]
    for k in range(3):  # three steps past the limit: said once
        checked(layer, 1.001 + 0.001 * k, q, fast, np.zeros(6))
    (said,) = [e for e in layer.interventions if e.rule == "velocity"]
    assert said.joint == hit.model.joint_names[4] and said.t == pytest.approx(1.001)
    assert said.value == pytest.approx(fast[4]) and said.limit == pytest.approx(hit.model.limits.velocity[4])
    assert [e.rule for e in layer.events] == ["e-stop"] and layer.category == 2  # the stop as it was
