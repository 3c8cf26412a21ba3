"""The force-torque sensor: tared, filtered, read by the safety envelope on every backend, with a test rig pushing on
the handle (the same trip force in simulation and over the link, HIT and L-Exos, with the sensor's bias and noise:
tests/test_safety_report.py)."""

from __future__ import annotations

import numpy as np
import pytest

from rehabkit.api import run_scenario
from rehabkit.cli import main
from rehabkit.core.scenario.loader import load_scenario
from tests.conftest import SCENARIOS
from tests.located import refusal, set_located

SAFETY = SCENARIOS / "safety"


def test_a_noiseless_sensor_reads_the_push_exactly_once_tared():
    """The mount is a 1 g body: the sensor reads the load on it, whatever the arm does."""
    r = run_scenario(SAFETY / "hit_force.yaml", {"sensors.ft.cutoff_hz": 0, "sensors.ft.simulated.noise_n": 0,
                                                 "safety": {"interaction_force_n": 1000}, "duration": 1.5,
                                                 "expect": {"safety_events": {"eq": 0}}})
    assert not r.summary["safety"]["events"]
    load = load_scenario(SAFETY / "hit_force.yaml").model.world.loads[0]
    expected = np.array([load.at(t) for t in r.trace.t]) * np.linalg.norm(load.force_n)
    moving = r.trace.t > 0.5  # past the tare (the robot held at its start, nothing pushing)
    assert np.abs(r.trace.f_h[moving] - expected[moving]).max() < 0.1


def test_a_force_limit_over_the_link_needs_a_force_sensor(capsys):
    hit = SCENARIOS / "hit_roundtrip.yaml"
    code = main(["validate", str(hit), "--set", "backend.type=hardware", "--set", "safety.interaction_force_n=40"])
    assert (code, set_located(capsys.readouterr().err)) == (
        2, [("safety.interaction_force_n", "safety.interaction_force_n")])  # (no source of the force over the link)
    assert main(["validate", str(hit), "--set", "backend.type=hardware", "--set", "safety.interaction_force_n=40",
                 "--set", "sensors.ft={type: force-torque}"]) == 0


def test_a_load_on_a_body_the_scene_lacks_is_refused_with_the_closest_names():
    (d,) = refusal(SAFETY / "hit_force.yaml", "world.loads.0.body=handel").diagnostics
    assert (d.mark.file, d.path) == ("<--set world.loads.0.body>", "world.loads.0.body")
    assert d.fix.startswith("choices: base, elbow_1_link, ")  # (none near 'handel': the scene's bodies)


def test_a_sensor_at_a_cuff_reads_the_strapped_persons_cuff_force():
    """The musculoskeletal patient's forearm strap is fastened to the sensor's mount (cuff_forearm): the sensor,
    zeroed before the person was strapped in (tare_s: 0), reads that strap's constraint force."""
    from rehabkit.core.run.runner import Runner

    runner = Runner(load_scenario(SCENARIOS / "hit_myoarm.yaml", {
        "sensors": {"cuff": {"type": "force-torque", "strap": "forearm", "cutoff_hz": 0, "tare_s": 0}},
        "duration": 1.0}))
    r = runner.run()
    times, cuffs = runner.setup.patient.series()["patient/cuff_force_n/forearm"]
    measured = np.interp(times, r.trace.t, r.trace.f_h)
    assert cuffs.max() > 5.0  # the arm's weight and its effort
    assert np.abs(measured - cuffs).max() < 0.05 * cuffs.max()


@pytest.mark.parametrize(("cutoff_hz", "fs"), [(30.0, 1000.0), (5.0, 100.0), (240.0, 500.0)])
def test_the_sensors_low_pass_is_scipys_butterworth(cutoff_hz, fs):
    """The filter's closed-form design, its start at rest and its run over a recording, against scipy.signal."""
    from rehabkit_plugins.sensors.force_torque import Biquads, butterworth2
    from scipy.signal import butter, sosfilt, sosfilt_zi

    sos = butterworth2(cutoff_hz, fs)
    assert np.allclose(sos, butter(2, cutoff_hz, fs=fs, output="sos"), rtol=1e-12, atol=1e-14)
    at = np.array([1.5, -2.0, 0.25])
    settled = Biquads(sos, 3)
    settled.settle(at)
    assert np.allclose(settled.z, sosfilt_zi(sos)[:, :, None] * at, atol=1e-12)
    assert np.allclose(settled(at), at)  # at rest: the output stays where it started
    xs = np.random.default_rng(3).normal(0.0, 1.0, (400, 3))
    assert np.allclose(Biquads(sos, 3).run(xs), sosfilt(sos, xs, axis=0), atol=1e-12)
