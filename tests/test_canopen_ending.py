"""How a run on CiA 402 drives ends, read from its CAN trace as any CAN tool reads it: the stop's reaction (quick
stop), the power stages off (disable voltage: SWITCH ON DISABLED), the drives' watch of the host's heartbeat
disarmed (0x1016), NMT pre-operational — the same whether the run ended normally or by a safety stop."""

import can
import pytest

from rehabkit.api import run_scenario
from rehabkit.canopen.cia402 import State
from tests.test_canopen_backend import CANOPEN, HIT, ROOT

NODES = range(1, 7)


def _tail(path):
    """The frames from the last controlword that is not 'enable operation' on."""
    frames = list(can.LogReader(path))
    ids = [f.arbitration_id for f in frames]
    enable = max(k for k, f in enumerate(frames) if f.arbitration_id == 0x201 and f.data[0] == 0x0F)
    return frames[enable + 1:], ids


def _ending_as_the_standards_say(tail):
    controlwords = [f.data[0] for f in tail if f.arbitration_id == 0x201]
    assert controlwords[0] == 0x02 and controlwords[-1] == 0x00  # quick stop, then disable voltage
    assert set(controlwords) == {0x02, 0x00}
    status = [int.from_bytes(f.data[:2], "little") for f in tail if 0x181 <= f.arbitration_id <= 0x186]
    assert all(State.of(s) is State.SWITCH_ON_DISABLED for s in status[-6:])  # every drive's last statusword
    sdo = [f for f in tail if 0x601 <= f.arbitration_id <= 0x606]
    assert [(f.data[0], f.data[1:4].hex(), f.data[4:8].hex()) for f in sdo] == [(0x23, "161001", "00000000")] * 6
    nmt = [bytes(f.data) for f in tail if f.arbitration_id == 0x000]
    assert nmt[:6] == [bytes([0x80, n]) for n in NODES] and {m[0] for m in nmt} == {0x80}  # each node pre-op
    last_nmt = max(k for k, f in enumerate(tail) if f.arbitration_id == 0x000)
    after = tail[last_nmt + 1:]  # (nothing from the drives but heartbeats: no EMCY, no PDO)
    assert not [f for f in after if 0x80 < f.arbitration_id < 0x100 or 0x180 <= f.arbitration_id < 0x580]
    return controlwords


def test_a_normal_end_leaves_the_drives_disabled_and_pre_operational(tmp_path):
    r = run_scenario(HIT, {**CANOPEN, "duration": 1.0}, out_dir=tmp_path)
    assert r.metrics["can_emcy"] == 0
    tail, _ = _tail(tmp_path / "can.asc")
    controlwords = _ending_as_the_standards_say(tail)
    assert len(controlwords) < 0.2 / 0.002  # at rest within 0.2 s: the arm was held still at the end


@pytest.mark.parametrize("scenario", ["hit_speed.yaml"])
def test_a_run_a_safety_stop_ended_ends_the_same_way(tmp_path, scenario):
    over = {**CANOPEN, "rates": {"control_hz": 250}}
    r = run_scenario(ROOT / "scenarios" / "safety" / scenario, over, out_dir=tmp_path)
    assert r.summary["safety"]["events"], "the scenario's stop did not come"
    tail, _ = _tail(tmp_path / "can.asc")
    _ending_as_the_standards_say(tail)


def test_drives_enabled_by_sdo_walk_and_end_by_sdo_and_carry_no_controlword_in_their_rpdo(tmp_path):
    """``enable: sdo``: each controlword the walk, the stop and the end need is an SDO download to 0x6040 (it acts at
    once in the drive), the RPDO carries the target torque alone; the run tracks as by PDO."""
    drives = [{"node_id": k, "enable": "sdo"} for k in NODES]
    r = run_scenario(HIT, {**CANOPEN, "duration": 1.0, "backend": {**CANOPEN["backend"], "drives": drives}},
                     out_dir=tmp_path)
    assert r.metrics["safety_events"] == 0 and r.metrics["can_emcy"] == 0
    frames = list(can.LogReader(tmp_path / "can.asc"))
    words = [f.data[4] for f in frames if f.arbitration_id == 0x601 and f.data[:4] == bytes([0x2B, 0x40, 0x60, 0])]
    assert words == [0x06, 0x00, 0x06, 0x07, 0x0F, 0x02, 0x00]  # set-up, the walk, quick stop and power off
    assert {f.dlc for f in frames if f.arbitration_id == 0x201} == {2}  # (the target torque: 2 bytes)


def test_ctrl_c_mid_motion_ends_the_same_way_and_a_second_one_does_not_cut_it_short(tmp_path, monkeypatch):
    """Ctrl-C at 1 s, mid-motion (KeyboardInterrupt raised in the loop's step, as SIGINT raises it), and a second one
    while the drives are stopping: the quick stop runs to rest all the same, then the power off and pre-operational."""
    import signal

    from rehabkit.canopen.backend import CanopenBackend

    step, close = CanopenBackend.step, CanopenBackend.close

    def interrupted(self, n=1):
        if self.cycles == 500:
            raise KeyboardInterrupt
        step(self, n)

    def close_pressed_again(self):
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN  # (a second Ctrl-C now is held off)
        close(self)

    monkeypatch.setattr(CanopenBackend, "step", interrupted)
    monkeypatch.setattr(CanopenBackend, "close", close_pressed_again)
    with pytest.raises(KeyboardInterrupt):
        run_scenario(HIT, CANOPEN, out_dir=tmp_path)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    tail, _ = _tail(tmp_path / "can.asc")
    controlwords = _ending_as_the_standards_say(tail)
    assert 10 < len(controlwords) < 0.3 / 0.002  # (moving at 1 s: the quick stop took its ramp)


def test_the_wrote_line_names_every_file_the_run_wrote(tmp_path):
    from tests.test_cli import cli

    out = tmp_path / "run"
    r = cli("run", str(HIT), "--set", "backend.type=canopen", "--set", "backend.clock=lockstep", "--set",
            "rates.control_hz=500", "--set", "duration=0.5", "--out", str(out))
    line = next(x for x in r.stdout.splitlines() if x.startswith("wrote "))
    named = {p.strip() for p in line[len("wrote "):].replace(" and ", ", ").split(", ")}
    assert named == {str(p) for p in out.iterdir()}  # summary, recording, scenario, safety log, CAN trace
    assert str(out / "can.asc") in named
