"""What a CANopen bus and its drives are set to before a run: the bus arithmetic validate refuses a rate by, its
refusals of drives that cannot be what the scenario asks, and the limits downloaded into each drive's objects."""

import numpy as np
import pytest
import yaml

from rehabkit.api import run_scenario
from rehabkit.canopen.bus.pdo_layout import bus_load, frame_bits
from tests.located import refusal, where
from tests.test_canopen_backend import CANOPEN, HIT, ROOT


def test_the_bus_arithmetic_counts_worst_case_frames():
    assert (frame_bits(0), frame_bits(4), frame_bits(6), frame_bits(8)) == (55, 95, 115, 135)  # Davis et al. 2007
    six = bus_load(6, 1000, 1_000_000, heartbeat_ms=1e9)
    assert six.bits_per_cycle == 6 * (95 + 115 + 95) + 55 and six.load > 1.8
    assert 500 < six.highest_rate_hz() < 531  # 6 axes fit at 500 Hz, not at 1 kHz
    assert bus_load(3, 1000, 1_000_000, heartbeat_ms=1e9).load < 1.0 < bus_load(4, 1000, 1_000_000).load


def test_validate_refuses_six_drives_at_1khz_at_the_control_rate_with_the_arithmetic():
    refused = refusal(ROOT / "scenarios" / "hit_roundtrip.yaml", "backend.type=canopen")
    assert where(refused) == [(37, 9, "rates.control_hz")], str(refused)
    (d,) = refused.diagnostics
    load = refused.__cause__.data["load"]  # (the arithmetic, as the bus load it was said from: 191% of 1000 kbit/s)
    assert (load.bits_per_cycle, load.bitrate, round(load.load, 2)) == (1885, 1_000_000, 1.91)
    assert d.fix == "set rates.control_hz: 500 (the highest rate that fits in whole 1 ms steps of the simulated " \
        "drives' plant; the bus carries up to 518 Hz), or put fewer nodes on this bus"


@pytest.mark.parametrize("backend, where, says", [
    ({"drives": [{"node_id": k} for k in (1, 2, 3, 3, 5, 6)]}, "backend.drives.3.node_id", "node id 3 is drive 2's"),
    ({"drives": [{"node_id": k} for k in (1, 2, 3)]}, "backend.drives", "3 drives for the 6 joints"),
    ({"drives": [{"node_id": 1, "eds": "nowhere.eds"}] + [{"node_id": k} for k in range(2, 7)]},
     "backend.drives.0.eds", "no such file"),
    ({"bus": {"interface": "socketcan", "channel": "can0"}}, "backend.clock", "lockstep runs the simulated drives"),
    ({"inject": [{"at_s": 1.0, "fault": "drive", "node": 9}]}, "backend.inject.0.node", "no drive has node id 9"),
])
def test_validate_refuses_a_bus_that_cannot_be_at_its_setting(tmp_path, backend, where, says):
    """As ``rehabkit validate`` checks a scenario (its setup but the backend, whose ``check`` it calls)."""
    from rehabkit.core.plugins.lifecycle import default_extensions
    from rehabkit.core.plugins.registry import default_registry
    from rehabkit.core.scenario.errors import ScenarioError
    from rehabkit.core.scenario.loader import load_scenario
    from rehabkit.core.setup.assembly import assemble

    scenario = tmp_path / "s.yaml"
    scenario.write_text(yaml.safe_dump({"extends": str(HIT), "rates": {"control_hz": 500},
                                        "backend": {"type": "canopen", "clock": "lockstep", **backend}}))
    with pytest.raises(ScenarioError) as err:
        assemble(load_scenario(scenario), default_registry(), default_extensions(), upto="plugins")
    diag = err.value.diagnostics[0]
    assert diag.path == where and says in diag.message


@pytest.mark.parametrize("scenario, says", [
    ("lexos_reaching.yaml", "a csp drive follows the plan's joint reference: this scenario's planner plans in "
                            "Cartesian space"),
    ("safety/hit_force_yield.yaml", "a csp drive holds its target stiffly: the envelope's interaction-force reaction "
                                    "(yield) needs the torque (mode: cst)"),
    ("hit_roundtrip.yaml", "the CAN bus cannot carry 6 drives at 500 Hz"),
])
def test_validate_refuses_position_drives_where_they_cannot_do_what_the_scenario_asks(tmp_path, scenario, says):
    from rehabkit.core.plugins.lifecycle import default_extensions
    from rehabkit.core.plugins.registry import default_registry
    from rehabkit.core.scenario.errors import ScenarioError
    from rehabkit.core.scenario.loader import load_scenario
    from rehabkit.core.setup.assembly import assemble

    n = 4 if scenario.startswith("lexos") else 6
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump({"extends": str(ROOT / "scenarios" / scenario), "rates": {"control_hz": 500},
                                    "backend": {**CANOPEN["backend"], "drives": [
                                        {"node_id": i + 1, "mode": "csp"} for i in range(n)]}}))
    with pytest.raises(ScenarioError) as err:
        assemble(load_scenario(path), default_registry(), default_extensions(), upto="plugins")
    assert says in err.value.diagnostics[0].message


def test_a_limit_more_counts_than_its_object_holds_is_told_its_largest_and_said(tmp_path):
    """A light wrist behind a 17-bit encoder and a 50:1 gear: half what its drive can give it, 5655 rad/s², is
    5.9e9 counts/s² — more than the quick stop deceleration's UNSIGNED32 holds. The drive is told the largest it
    holds and the run says so (the run crashed in its set-up before, with a ValueError and a run.rrd.tmp left)."""
    drives = [{"node_id": 1}, {"node_id": 2}, {"node_id": 3}, {"node_id": 4, "gear_ratio": 50}]
    r = run_scenario(ROOT / "examples" / "robots" / "urdf_arm4.yaml",
                     {"duration": 1.0, "rates.control_hz": 500,
                      "backend": {"type": "canopen", "clock": "lockstep", "drives": drives}}, out_dir=tmp_path)
    (note,) = [n["text"] for n in r.summary["notes"] if "0x6085" in n["text"]]
    counts_per_rad = 131072 * 50 / (2 * np.pi)
    assert note.startswith("drive 4 (wrist): its quick stop deceleration, 5655 rad/s²")
    assert note.endswith(f"told its largest, {(2**32 - 1) / counts_per_rad:.4g} rad/s²")
    assert r.metrics["safety_events"] == 0 and r.metrics["tracking_rms_deg"] < 1.0
    assert not list(tmp_path.glob("*.tmp")) and (tmp_path / "summary.json").exists()


def test_validate_says_a_bus_that_fits_but_is_nearly_full():
    """Six drives at 500 Hz take 96.5 % of 1 Mbit/s: valid (exit 0), and said — an SDO or a retried frame mid-run
    has little room."""
    from tests.test_cli import cli

    r = cli("validate", str(HIT), "--set", "backend.type=canopen", "--set", "rates.control_hz=500", "--set",
            "backend.clock=lockstep")
    assert r.returncode == 0
    assert "  BACKEND the CAN bus is 96.5% full at 500 Hz (1885 bits a cycle, worst-case stuffing)" in r.stdout
