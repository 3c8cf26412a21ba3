"""Kalman filtering and rigid-body motion from accelerometers (CaPaMan validation chain)."""

import numpy as np
import pytest

from rehabkit.estimation.kalman import ConstantRateModel, KalmanBank
from rehabkit.estimation.rigid_body import AccelerometerArray, AngularVelocityEKF

TETRA = np.array([(0.08, 0, 0), (-0.04, 0.0693, 0), (-0.04, -0.0693, 0), (0, 0, -0.05)])


def rigid_motion(dt=0.001, duration=6.0):
    t = np.arange(0.0, duration, dt)
    ramp = np.minimum(t, 1.0)[:, None]  # from rest, as a robot starts
    w = ramp * np.stack([0.8 * np.sin(1.3 * t), 0.5 * np.cos(0.9 * t) + 0.2, 0.6 * np.sin(0.7 * t + 1)], 1)
    alpha = np.gradient(w, dt, axis=0)
    a = np.stack([2 * np.sin(2 * t), np.cos(1.5 * t), 9.81 + 0.5 * np.sin(t)], 1)
    readings = np.stack([a + np.cross(alpha, r) + np.cross(w, np.cross(w, r)) for r in TETRA], 1)
    return t, a, w, readings


def rms(e):
    return float(np.sqrt(np.mean(np.square(e))))


def test_design_matrix_reconstructs_exactly_and_refuses_coplanar_layouts():
    arr = AccelerometerArray(TETRA)
    _, a, w, readings = rigid_motion(duration=1.0)
    z = np.array([arr.solve(y) for y in readings])
    np.testing.assert_allclose(z[:, :3], a, atol=1e-9)
    np.testing.assert_allclose(z[:, 6:9], w**2, atol=1e-9)
    flat = [(0.08, 0, 0), (0, 0.08, 0), (-0.08, 0, 0), (0, -0.08, 0)]
    with pytest.raises(ValueError, match="only 9 of the 12"):
        AccelerometerArray(flat)


def test_kalman_filter_beats_raw_noise_threefold():
    dt = 0.001
    t, _, _, readings = rigid_motion(dt)
    rng = np.random.default_rng(3)
    noisy = readings + rng.normal(0, 0.5, readings.shape)
    bank = KalmanBank(ConstantRateModel(dt), 4)
    filtered = np.array([bank.step(y) for y in noisy])
    settle = 500
    assert rms(filtered[settle:] - readings[settle:]) < rms(noisy[settle:] - readings[settle:]) / 3


def test_angular_velocity_ekf_is_far_better_than_the_algebraic_estimate():
    dt = 0.001
    _, _, w, readings = rigid_motion(dt)
    rng = np.random.default_rng(4)
    noisy = readings + rng.normal(0, 0.5, readings.shape)
    arr, naive_arr = AccelerometerArray(TETRA), AccelerometerArray(TETRA)
    bank, ekf = KalmanBank(ConstantRateModel(dt), 4), AngularVelocityEKF()
    naive, fused = [], []
    for y in noisy:
        f = bank.step(y)
        var = bank.P[:, 0::2, 0::2].diagonal(axis1=1, axis2=2).ravel()
        z = arr.solve(f)
        fused.append(ekf.step(z, arr.M_pinv @ np.diag(var) @ arr.M_pinv.T, dt))
        naive.append(naive_arr.omega(naive_arr.solve(y), dt))
    settle = 1000
    assert rms(np.array(fused)[settle:] - w[settle:]) < 0.3
    assert rms(np.array(naive)[settle:] - w[settle:]) > 3 * rms(np.array(fused)[settle:] - w[settle:])


def test_mujoco_accelerometers_obey_the_rigid_body_model(tmp_path):
    """Noiseless MuJoCo readings at the mounting points reconstruct the origin's readings."""
    from rehabkit.core.run.runner import Runner
    from rehabkit.core.scenario.loader import load_scenario
    from tests.conftest import SCENARIOS

    runner = Runner(load_scenario(SCENARIOS / "hit_roundtrip.yaml", {
        "sensors": {"imu": {"type": "accelerometer-array", "body": "elbow_2_link", "rate_hz": 1000,
                            "noise_std": [1e-9, 1e-9, 1e-9], "offset_std": 0.0}}, "duration": 3.0, "expect": None}))
    result = runner.run()
    imu = runner.sensors["imu"]
    assert result.passed
    # with (almost) no noise both estimates match the truth
    assert result.metrics["accel_rms_raw_m_s2"] < 1e-3
    assert result.metrics["omega_rms_filtered_rad_s"] < 0.05
    reading = runner.observations["imu"]
    np.testing.assert_allclose(reading["acc_raw"], reading["acc_true"], atol=1e-3)
    assert np.linalg.norm(reading["acc_true"]) == pytest.approx(9.81, abs=0.5)  # at rest at E: reads +g
    assert imu.instruments()[-1].kind == "gyro"


def test_filtering_cuts_error_threefold_on_a_real_run(run_scenario):
    from tests.conftest import SCENARIOS

    r = run_scenario(SCENARIOS / "hit_roundtrip.yaml", write=False,
                     sensors={"imu": {"type": "accelerometer-array", "body": "elbow_2_link", "rate_hz": 1000}})
    assert r.passed
    assert r.metrics["accel_filter_gain"] > 3 and r.metrics["omega_filter_gain"] > 3
