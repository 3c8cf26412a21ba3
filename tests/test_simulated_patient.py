"""The simulated patient's arm term by term, and assist-as-needed against it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rehabkit_plugins.controllers.assist_as_needed import AssistAsNeeded, AssistAsNeededConfig
from rehabkit_plugins.patients.simulated_arm import SimulatedArm, SimulatedArmConfig

from rehabkit.api import run_scenario
from rehabkit.core.kinds.interfaces import Context
from tests.conftest import SCENARIOS

DT = 1e-3


def _arm(robot, space="joint", seed=0, **cfg):
    ctx = Context(Path("."), np.random.default_rng(seed), DT, robot=robot, reference_space=space, seed=seed)
    return SimulatedArm(SimulatedArmConfig.model_validate(cfg), ctx)


QUIET = {"voluntary": {"strength_nm": 1.0, "participation": 0.0, "noise": 0.0}}


def test_passive_tissue_is_a_spring_to_rest_and_a_damper(hit):
    rest = [10, 80, 60, 20, -60, 60]
    arm = _arm(hit, stiffness_nm_rad=2.0, damping_nms_rad=0.5, rest_deg=rest, **QUIET)
    q = np.radians(rest) + 0.1
    qd = np.full(6, 0.2)
    assert arm.torque(0.0, q, qd, q) == pytest.approx(-2.0 * 0.1 - 0.5 * 0.2)


def test_spastic_resistance_grows_with_speed_above_the_threshold_after_the_reflex_delay(hit):
    arm = _arm(hit, stiffness_nm_rad=0.0, damping_nms_rad=0.0, **QUIET,
               spasticity={"gain_nms_rad": 3.0, "threshold_deg_s": 30, "reflex_delay_s": 0.02})
    q = np.radians([10, 80, 60, 20, -60, 60])
    torques = [arm.torque(k * DT, q, np.full(6, 1.5), q) for k in range(40)]  # 86 °/s, above the 30 °/s threshold
    assert np.allclose(torques[19], 0.0)  # nothing before the reflex delay
    assert torques[25] == pytest.approx(-3.0 * (1.5 - np.radians(30)))
    slow = _arm(hit, stiffness_nm_rad=0.0, damping_nms_rad=0.0, **QUIET,
                spasticity={"gain_nms_rad": 3.0, "threshold_deg_s": 30, "reflex_delay_s": 0.0})
    assert np.allclose([slow.torque(k * DT, q, np.full(6, 0.4), q) for k in range(5)], 0.0)  # 23 °/s: none


def test_voluntary_effort_goes_for_the_goal_and_fatigue_wears_it_down(hit):
    arm = _arm(hit, stiffness_nm_rad=0.0, damping_nms_rad=0.0,
               voluntary={"strength_nm": 4.0, "stiffness": 100.0, "damping": 0.0, "noise": 0.0},
               fatigue={"rate_per_s": 0.5, "recovery_per_s": 0.0})
    q = np.radians([10, 80, 60, 20, -60, 60])
    goal = q + 0.2
    first = arm.torque(0.0, q, np.zeros(6), goal)
    assert np.all(first > 0) and first.max() <= 4.0  # toward the goal, capped at the strength
    for k in range(1, 2000):
        last = arm.torque(k * DT, q, np.zeros(6), goal)
    assert arm.capacity < 0.6 and np.all(last < 0.6 * first)  # two seconds of full effort: tired
    rested = _arm(hit, stiffness_nm_rad=0.0, damping_nms_rad=0.0,
                  voluntary={"strength_nm": 4.0, "stiffness": 100.0, "noise": 0.0},
                  fatigue={"rate_per_s": 0.5, "recovery_per_s": 1.0})
    rested.capacity = 0.5
    for k in range(3000):
        rested.torque(k * DT, q, np.zeros(6), q)  # no effort: recovers
    assert rested.capacity > 0.9


def test_the_patients_noise_is_its_own_stream(hit):
    a, b = _arm(hit, seed=3), _arm(hit, seed=3)
    q = np.radians([10, 80, 60, 20, -60, 60])
    np.random.default_rng([3]).normal(size=100)  # other draws don't matter
    ta = [a.torque(k * DT, q, np.zeros(6), q + 0.1) for k in range(500)]
    tb = [b.torque(k * DT, q, np.zeros(6), q + 0.1) for k in range(500)]
    assert np.array_equal(ta, tb) and np.std(np.array(ta)[:, 0]) > 0  # noisy, and the same noise
    assert a.inputs() == b.inputs() != _arm(hit, seed=4).inputs()


def test_assistance_grows_while_the_person_lags_and_fades_when_they_keep_up(hit):
    ctx = Context(Path("."), np.random.default_rng(0), DT, robot=hit, reference_space="joint")
    aan = AssistAsNeeded(AssistAsNeededConfig(k_min=10, k_max=500, gain=2000, dead_band=0.01, forgetting_s=1.0),
                         ctx)
    q = np.radians([10, 80, 60, 20, -60, 60])
    z = np.zeros(6)
    for k in range(1000):  # 0.1 rad behind on every joint for a second
        aan.compute(k * DT, q, z, q + 0.1, z, z)
    assert np.all(aan.k > 50)
    grown, helped = aan.k.copy(), aan.f_a.copy()
    assert np.all(helped > 0)
    for k in range(1000, 4000):  # then on the reference
        aan.compute(k * DT, q, z, q, z, z)
    assert np.all(aan.k < 0.2 * grown) and np.all(np.abs(aan.f_a) < 0.1 * helped)


def test_assist_as_needed_drives_the_hit_round_trip_by_changing_the_controller():
    result = run_scenario(SCENARIOS / "hit_roundtrip.yaml", ["controller.type=assist-as-needed",
                                                              "controller.k_max=2000"])
    m = result.metrics
    assert result.summary["safety"]["events"] == []
    assert m["reaches"] == 4 and m["reaches_completed"] == 4  # every via point, within 1 cm
    assert m["aan_stiffness_max"] > m["aan_stiffness_mean"] > 50  # it had to help, and not all the time


def test_the_per_step_hand_force_is_the_least_squares_one(hit, lexos):
    from rehabkit.models.hand_force import HandForce
    from rehabkit.rehab.outcomes import interaction_forces

    rng = np.random.default_rng(2)
    for robot in (hit, lexos):
        hf, lim = HandForce(robot.model), robot.model.limits
        qs = rng.uniform(lim.lower, lim.upper, (20, robot.model.dof))
        taus = rng.normal(size=(20, robot.model.dof))
        step = np.array([hf(q, tau) for q, tau in zip(qs, taus)])
        assert np.allclose(step, interaction_forces(np.stack([hf.jacobian(q) for q in qs]), taus), atol=1e-8)


def test_no_voluntary_push_out_of_the_active_range(hit):
    from rehabkit.rehab.patient import PatientBase

    profile = PatientBase.model_validate({"id": "T2", "side": "right",
                                         "joints": {"elbow_1": {"passive_deg": [20, 120], "active_deg": [40, 95]}}})
    ctx = Context(Path("."), np.random.default_rng(0), DT, robot=hit, reference_space="joint", patient=profile)
    arm = SimulatedArm(SimulatedArmConfig.model_validate(
        {"stiffness_nm_rad": 0.0, "damping_nms_rad": 0.0, "end_range": {"torque_nm": 0.0},
         "voluntary": {"stiffness": 50.0, "noise": 0.0}}), ctx)
    q = np.radians([0, 90, 95, 30, -90, 90])  # elbow_1 at the top of its active range
    tau = arm.torque(0.0, q, np.zeros(6), q + np.radians(10))  # every joint's goal 10° further
    assert tau[2] == 0.0 and np.all(np.delete(tau, 2) > 0)  # the elbow can't go further on its own; the rest push
    assert arm.torque(0.001, q, np.zeros(6), q - np.radians(10))[2] < 0  # back into the range it can
