"""The musculoskeletal patient against known answers, on a one-joint elbow dynamometer (a user's robot, with the
person's fit in its scenario: examples/robots/elbow_dynamometer.yaml) and on MyoArm in the L-Exos.

The bench (:mod:`rehabkit.musculo.dynamometer`) steps the assembled scene itself, as a clinical dynamometer would:
the lever held (isometric), driven at a set speed (isokinetic, a Tardieu test), or left free with its own weight
compensated (transparent); the person's torque is what the straps put on the lever.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from rehabkit.core.run.runner import Runner
from rehabkit.core.scenario.loader import load_scenario
from rehabkit.musculo.dynamometer import MVC, RIGID, Dynamometer, isometric, tardieu
from rehabkit.musculo.static_opt import StaticOptimisation
from tests.conftest import ROOT, SCENARIOS

DYNO = ROOT / "examples" / "robots" / "elbow_dynamometer.yaml"


def _bench(overrides: dict | None = None, driven: bool = False, q0: float = 0.0) -> Dynamometer:
    return Dynamometer(DYNO, overrides, driven, q0)


def _isometric(overrides: dict | None = None) -> tuple[float, float]:
    return isometric(DYNO, overrides)


def _tardieu(speed_deg_s: float, overrides: dict) -> tuple[float, float]:
    return tardieu(DYNO, speed_deg_s, overrides)


def test_weakness_scales_the_isometric_elbow_flexion_torque_in_proportion():
    full, rest_full = _isometric()
    half, rest_half = _isometric({"patient.model.weakness": {"elbow_flexors": 0.5}})
    # the lever is pushed toward extension (its +q) by a flexing person: the torque on it is negative
    assert full - rest_full < -20.0  # an adult's elbow flexors: tens of N·m
    assert rest_half == pytest.approx(rest_full, abs=0.05)  # passive tissue is not weakened
    assert (half - rest_half) / (full - rest_full) == pytest.approx(0.5, abs=0.02)


def _reflex_speed(bench: Dynamometer, threshold_l0_s: float) -> float:
    """The elbow speed [°/s] at which the most sensitive flexor is stretched at the threshold, at 90° of flexion
    (its optimal length and moment arm from the model): where a Tardieu test should find the catch."""
    m, d, arm = bench.m, bench.d, bench.person.arm
    moment = np.zeros((m.nu, m.nv))
    mujoco.mju_sparse2dense(moment, d.actuator_moment, d.moment_rownnz, d.moment_rowadr, d.moment_colind)
    flexors = arm.groups["elbow_flexors"]
    arms = np.abs(moment[arm.muscles[flexors], arm.driven[0]])
    return float(np.degrees(np.min(threshold_l0_s * arm.l0[flexors] / arms)))


@pytest.mark.parametrize("spastic", [True, False])
def test_a_fast_stretch_meets_a_reflex_only_above_the_threshold_speed(spastic):
    gain = {"patient.model.spasticity": {"gain": {"elbow_flexors": 0.5}, "threshold_l0_s": 0.3}} if spastic else {}
    catch = _reflex_speed(_bench(), 0.3)
    assert 30.0 < catch < 60.0  # the biceps' L₀ and moment arm put it near 45°/s
    speeds = (0.3 * catch, 0.6 * catch, 3 * catch, 6 * catch)
    resist = {v: _tardieu(v, gain) for v in speeds}
    if not spastic:  # no reflex at any speed: the flexors stay silent
        assert all(excite == 0.0 for _, excite in resist.values())
        return
    slow, slower, fast, faster = (resist[v] for v in speeds)
    assert slow[1] == 0.0 and slower[1] == 0.0  # below the threshold: nothing beyond the passive tissue
    assert slow[0] == pytest.approx(_tardieu(speeds[0], {})[0], abs=0.05)
    assert fast[1] > 0.0 and faster[1] > fast[1]  # above: a catch, growing with speed
    assert faster[0] - _tardieu(speeds[3], {})[0] > 2.0


def test_tremor_puts_a_peak_in_the_hands_speed_spectrum_at_its_frequency():
    def spectrum(amplitude: float):
        bench = _bench({"patient.model.tremor": {"amplitude_nm": {"elbow_flexion": amplitude}, "frequency_hz": 5.0}})
        rec = bench.run(4.0)  # holding the forearm still, the lever free
        speed = rec["qd"][100:] * 0.25  # the hand's speed on the 0.25 m lever [m/s]
        power = np.abs(np.fft.rfft(speed - speed.mean())) ** 2
        return np.fft.rfftfreq(len(speed), bench.dt), power

    f, with_tremor = spectrum(0.4)
    _, without = spectrum(0.0)
    assert f[np.argmax(with_tremor[f > 1.0]) + np.count_nonzero(f <= 1.0)] == pytest.approx(5.0, abs=0.5)
    band = (f > 4.0) & (f < 6.0)
    assert with_tremor[band].sum() > 100 * without[band].sum()


def test_fatigue_lowers_the_maximal_torque_under_a_sustained_effort_and_it_recovers():
    bench = _bench({**RIGID, "patient.model.fatigue": {"rate_per_s": 0.3, "recovery_per_s": 0.3}}, driven=True)
    hold = lambda t: (0.0, 0.0)  # noqa: E731
    sustained = bench.run(3.0, request=lambda t: MVC, lever=hold)["tau"]
    fresh, tired = sustained[25:50].mean(), sustained[-25:].mean()
    assert tired / fresh < 0.7
    assert bench.person.run_metrics(None)["muscle_capacity_min"] < 0.5
    bench.run(10.0, request=lambda t: np.zeros(1), lever=hold)  # rest
    assert bench.person.run_metrics(None)["muscle_capacity_min"] > 0.9
    again = bench.run(0.3, request=lambda t: MVC, lever=hold)["tau"][-25:].mean()
    assert again / fresh > 0.9


def test_cuff_forces_stay_near_zero_while_person_and_robot_move_together_unloaded():
    reach = {"patient.model.drive.participation": 1.0}
    bench = _bench(reach)  # the soft cuffs of the example, the lever free and its weight compensated
    still = bench.run(0.5)  # the person holds their own forearm
    assert still["force"][50:].max() < 0.5
    moving = bench.run(1.5, goal=np.radians([-30.0]))  # they flex the elbow 30°, carrying the light lever along
    assert moving["q"][-1] < np.radians(-20.0)
    assert moving["force"].max() < 3.0
    held = _bench(reach, driven=True)  # the same move against a lever that stays put: the cuff takes the effort
    held_run = held.run(1.5, goal=np.radians([-30.0]), lever=lambda t: (0.0, 0.0))
    assert held_run["force"].max() > 5 * moving["force"].max()


def test_static_optimisation_reproduces_a_torque_within_capacity_and_reports_saturation_beyond():
    bench = _bench()
    so: StaticOptimisation = bench.person.so
    A, passive = so.matrices()
    within = so.solve(np.array([5.0]), A, passive)
    assert not within.saturated and within.torque == pytest.approx([5.0], abs=1e-3)
    assert np.all((within.activation >= 0) & (within.activation <= 1))
    beyond = so.solve(MVC, A, passive)
    assert beyond.saturated and beyond.torque[0] < MVC[0]
    flexors = bench.person.arm.groups["elbow_flexors"]
    assert np.allclose(beyond.activation[flexors], 1.0, atol=1e-3)  # everything the flexors have
    # and it is the most the muscles can give: all flexors on, extensors off
    full = np.zeros(len(within.activation))
    full[flexors] = 1.0
    assert beyond.torque[0] == pytest.approx((A @ full + passive)[0], rel=1e-3)


def test_myoarm_is_sized_to_the_profile_and_fits_the_lexos_axes():
    a = Runner(load_scenario(SCENARIOS / "lexos_myoarm.yaml")).build()
    a.backend.reset(np.radians([20.0, -45.0, 0.0, -70.0]))
    person, m, d = a.patient, a.backend.model, a.backend.data
    arm = person.arm
    shoulder, elbow = d.xpos[arm.body["shoulder"]], d.xpos[arm.body["elbow"]]
    assert np.linalg.norm(elbow - shoulder) == pytest.approx(0.30, abs=1e-4)  # the profile's upper_arm
    wrist = d.xpos[m.body("human/lunate_r").id]
    assert np.linalg.norm(wrist - elbow) == pytest.approx(0.35 - 0.07, abs=0.005)  # forearm: elbow to the grip
    assert shoulder == pytest.approx(a.robot.model.base_pose[:3, 3], abs=1e-3)  # where the L-Exos axes meet
    robot_elbow = m.joint("q4_elbow").id
    off_axis = np.cross(elbow - d.xanchor[robot_elbow], d.xaxis[robot_elbow])
    assert np.linalg.norm(off_axis) < 0.005  # the person's elbow on the exoskeleton's elbow axis
    assert person.offset < 1e-3  # each strap on its segment's axis
    hold = person.arm.coupling_matrix().T @ d.qfrc_bias
    solution = person.so.solve(hold)
    assert not solution.saturated and solution.torque == pytest.approx(hold, abs=1e-3)
    assert mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_EQUALITY, "human/strap_forearm") >= 0


def test_a_contracture_stops_the_elbow_short_of_extension():
    # a slow stretch (no reflex) from 100° toward 20° of flexion, with extension lost beyond 50°
    free, _ = _tardieu(15, {})
    stiff, _ = _tardieu(15, {"patient.model.contracture_deg": {"elbow_flexion": [50, 130]}})
    assert free < 3.0 and stiff > 10 * free
