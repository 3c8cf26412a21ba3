"""The force-torque sensor: tared, filtered, read by the safety envelope on every backend — in simulation and over a
hardware link (the bridge's plant reads it and sends it with each state), with a test rig pushing on the handle."""

from __future__ import annotations

import numpy as np
import pytest

from rehabkit.api import run_scenario
from rehabkit.cli import main
from rehabkit.core.scenario.loader import load_scenario
from tests.conftest import SCENARIOS

SAFETY = SCENARIOS / "safety"
LINK = {"backend": {"type": "hardware", "clock": "lockstep"}}


@pytest.mark.parametrize("name", ["hit_force"])  # (L-Exos's: tests/test_safety_report.py, with HIT's again)
def test_the_force_limit_trips_at_the_same_force_in_simulation_and_over_the_link(name):
    path = SAFETY / f"{name}.yaml"
    sc = load_scenario(path).model
    sim, link = run_scenario(path), run_scenario(path, LINK)
    (a,), (b,) = sim.summary["safety"]["events"], link.summary["safety"]["events"]
    limit = sc.safety.interaction_force_n
    assert a["rule"] == b["rule"] == "interaction-force" and a["limit"] == b["limit"] == limit
    assert abs(a["value"] - b["value"]) < 0.1 and abs(a["t"] - b["t"]) <= 0.002
    # what tripped it is the rig's push, read through the sensor: the push at the trip was the limit (the filter's
    # lag, ~8 ms at 30 Hz, lets it rise a little further)
    load = sc.world.loads[0]
    pushed = load.at(a["t"]) * np.linalg.norm(load.force_n)
    assert limit <= a["value"] < limit + 0.5 and abs(pushed - a["value"]) < 1.0
    for r in (sim, link):  # the tare took the sensor's offset off, the filter most of its noise
        m, err = r.summary["metrics"], sc.sensors["ft"].simulated
        assert m["ft_bias_n"] == pytest.approx(np.linalg.norm(err.bias_n), abs=0.1)
        assert m["ft_noise_n"] == pytest.approx(err.noise_n, rel=0.2)
        assert m["ft_noise_filtered_n"] < m["ft_noise_n"] / 3
        assert m["peak_interaction_force_n"] == pytest.approx(m["ft_peak_force_n"])


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
    assert code == 2 and "needs a source of the force: a force-torque sensor" in capsys.readouterr().err
    assert main(["validate", str(hit), "--set", "backend.type=hardware", "--set", "safety.interaction_force_n=40",
                 "--set", "sensors.ft={type: force-torque}"]) == 0


def test_a_load_on_a_body_the_scene_lacks_is_refused_with_the_closest_names(capsys):
    code = main(["validate", str(SAFETY / "hit_force.yaml"), "--set", "world.loads.0.body=handel"])
    err = capsys.readouterr().err
    assert code == 2 and "no body 'handel'" in err


def test_a_sensor_at_a_cuff_reads_the_strapped_persons_cuff_force():
    """The musculoskeletal patient's forearm strap is fastened to the sensor's mount (cuff_forearm): the sensor,
    zeroed before the person was strapped in (tare_s: 0), reads that strap's constraint force."""
    from rehabkit.core.runner import Runner

    runner = Runner(load_scenario(SCENARIOS / "hit_myoarm.yaml", {
        "sensors": {"cuff": {"type": "force-torque", "strap": "forearm", "cutoff_hz": 0, "tare_s": 0}},
        "duration": 1.0}))
    r = runner.run()
    times, cuffs = runner.setup.patient.series()["patient/cuff_force_n/forearm"]
    measured = np.interp(times, r.trace.t, r.trace.f_h)
    assert cuffs.max() > 5.0  # the arm's weight and its effort
    assert np.abs(measured - cuffs).max() < 0.05 * cuffs.max()
