"""The CANopen master against real drives' object dictionaries (tests/data/canopen_eds/, SOURCES.md says where each
comes from): what it reads of each file (its PDOs, modes, units), what ``validate`` says of a robot on six of them,
and the run itself, the simulated drives serving each file's dictionary — every file runs or is refused at its
line, saying what the drive lacks."""

import math
from pathlib import Path

import can
import numpy as np
import pytest
import yaml

from rehabkit.canopen.bus.drive_dictionary import read_dictionary
from rehabkit.canopen.bus.pdo_layout import needed
from rehabkit.canopen.bus.pdo_plan import PdoPlanError, plan_pdos
from rehabkit.canopen.config import DriveSpec
from rehabkit.canopen.drives.units import declared_units

ROOT = Path(__file__).resolve().parents[1]
EDS = ROOT / "tests" / "data" / "canopen_eds"
HIT = ROOT / "scenarios" / "hit_roundtrip.yaml"


def _refusal(tmp_path, backend: dict, rate: float = 250):
    """What ``validate`` refuses of HIT on ``backend`` (None: valid), as the CLI checks it: the ``ScenarioError``."""
    from rehabkit.core.plugins.lifecycle import default_extensions
    from rehabkit.core.plugins.registry import default_registry
    from rehabkit.core.scenario.errors import ScenarioError
    from rehabkit.core.scenario.loader import load_scenario
    from rehabkit.core.setup.assembly import assemble

    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump({"extends": str(HIT), "rates": {"control_hz": rate},
                                    "backend": {"type": "canopen", "clock": "lockstep", **backend}}))
    try:
        assemble(load_scenario(path), default_registry(), default_extensions(), upto="plugins")
    except ScenarioError as err:
        return err
    return None


def _validate(tmp_path, backend: dict, rate: float = 250):
    """``validate``'s first diagnostic of HIT on ``backend`` (None: valid), as the CLI checks it."""
    err = _refusal(tmp_path, backend, rate)
    return None if err is None else err.diagnostics[0]


def _refused(tmp_path, backend: dict, rate: float = 250):
    """What the backend refused, as the plugin raised it: the ``SettingError`` behind ``validate``'s diagnostic (its
    ``data``: the values the problem names)."""
    return _refusal(tmp_path, backend, rate).__cause__


def _six(name: str, **kw) -> list[dict]:
    return [{"node_id": k, "eds": str(EDS / name), **kw} for k in range(1, 7)]


def test_the_master_reads_each_files_pdos_as_the_file_has_them():
    """PDO counts, enabled ones (COB-ID bit 31), writable maps: what the files' own headers say (SOURCES.md)."""
    nanotec = read_dictionary(EDS / "nanotec_C5-E-2-09.eds", 5)
    assert (len(nanotec.rpdos), len(nanotec.tpdos)) == (8, 8)
    assert [s.enabled for s in nanotec.tpdos] == [True] * 4 + [False] * 4
    assert nanotec.tpdos[0].cob_id == 0x185 and nanotec.rpdos[2].cob_id == 0x405  # ($NODEID resolved)
    maxon = read_dictionary(EDS / "maxon_EPOS4-Module-50-5.eds", 1)
    assert [s.enabled for s in maxon.tpdos] == [True, False, False, False] and maxon.supported_modes is None
    zeroerr = read_dictionary(EDS / "zeroerr_eDriver-V1.5.eds", 1)
    assert [s.enabled for s in zeroerr.rpdos] == [True, False, False, False]
    assert zeroerr.supported_modes == 0x38D
    assert read_dictionary(EDS / "faulhaber_MCLM300x-CO.eds", 1).supported_modes == 0x25


def test_a_files_dictionary_for_any_node_is_what_canopen_parses_for_that_node():
    """A file is parsed once for node 1 (rehabkit.canopen.bus.drive_dictionary: 5-65 ms a parse, six drives of one
    file): node 127's dictionary made from it is, object by object and attribute by attribute, canopen's own parse of
    the file for node 127 — its COB-IDs ($NODEID+...) the node's (the generic servo's, every run's), a DCF's values
    given as $NODEID+... (Elmo's ParameterValue) and its commissioned node id (maxon's) the ones asked for. (Every
    file here, for node ids 1-127, compared the same when it was written; these three stand for the three kinds.)"""
    import warnings

    import canopen

    from rehabkit.canopen.bus.drive_dictionary import object_dictionary

    def attributes(od):
        out = {"node_id": od.node_id}
        for index in od.indices:
            obj = od[index]
            for var in obj.subindices.values() if hasattr(obj, "subindices") else (obj,):
                out[index, var.subindex] = {k: v for k, v in vars(var).items() if k != "parent"}
        return out

    relative = 0
    for path in (ROOT / "rehabkit" / "canopen" / "eds" / "cia402_servo.eds", EDS / "elmo_Gold-Drive.dcf",
                 EDS / "maxon_EPOS4-Module-50-15_node1.dcf"):
        with warnings.catch_warnings():  # (vendors' files carry what canopen warns of and reads anyway)
            warnings.simplefilter("ignore")
            ours, theirs = attributes(object_dictionary(path, 127)), attributes(canopen.import_od(str(path), 127))
        assert ours == theirs, path.name
        relative += sum(bool(v.get("relative")) for v in theirs.values() if isinstance(v, dict))
    assert relative == 5 + 9 + 11  # (their COB-IDs as $NODEID+...)
    assert object_dictionary(EDS / "elmo_Gold-Drive.dcf", 127)[0x1800][1].value == 0x180 + 127
    assert object_dictionary(EDS / "maxon_EPOS4-Module-50-15_node1.dcf", 127).node_id == 127


def test_four_tpdos_with_two_disabled_plan_only_what_the_run_needs():
    """The independent tester's case: TPDO3 and TPDO4 disabled. The run maps TPDO1 and TPDO2 and leaves the
    others as they are (it used to unsubscribe every TPDO: KeyError 901 on the disabled ones)."""
    d = read_dictionary(EDS / "zeroerr_eDriver-V1.5.eds", 1)
    rx, tx = needed(d, "cst")
    plan = plan_pdos(d, 1, rx, tx)
    assert [(p.slot.name, p.cob_id, p.entries) for p in plan.rx] == [("RPDO1", 0x201, ((0x6040, 0, 16),
                                                                                        (0x6071, 0, 16)))]
    assert [(p.slot.name, p.cob_id, len(p.entries)) for p in plan.tx] == [("TPDO1", 0x181, 2), ("TPDO2", 0x281, 1)]
    assert plan.others == () and all(p.bytes <= 8 for p in (*plan.rx, *plan.tx))
    elmo = read_dictionary(EDS / "elmo_Gold-Drive.dcf", 1)  # its TPDO3 and TPDO4 stay, synchronous: in the load
    assert [(s.name, share) for s, share in plan_pdos(elmo, 1, *needed(elmo, "cst")).others] == [("TPDO3", 1.0),
                                                                                                  ("TPDO4", 1.0)]


def test_an_object_the_drive_cannot_map_is_refused_with_its_line():
    d = read_dictionary(EDS / "elmo_Gold-Drive.dcf", 1)  # 0x6072 max torque: PDOMapping=0 there
    with pytest.raises(PdoPlanError) as err:
        plan_pdos(d, 1, [(0x6040, 0, 16), (0x6072, 0, 16)], [])
    line = next(n for n, t in enumerate((EDS / "elmo_Gold-Drive.dcf").read_text("latin-1").splitlines(), 1)
                if t.strip() == "[6072]")
    # the object, where the file says it may not be mapped, and CiA 301's abort for it (object cannot be mapped)
    assert (err.value.index, err.value.where, err.value.abort) == (0x6072, f"elmo_Gold-Drive.dcf:{line}", 0x06040041)


def test_each_drive_declares_its_units_and_the_limits_are_written_in_them():
    """maxon and Nanotec declare rev/min (0x60A9 = 0x00B44700): 1 rad/s at a joint behind 50:1 is 477.5 rpm at the
    motor; a drive declaring none takes velocities in position units per second."""
    spec = DriveSpec(node_id=1, gear_ratio=50, encoder_counts=4096)
    maxon = declared_units(spec.units(100.0), read_dictionary(EDS / "maxon_EPOS4-Module-50-5.eds", 1))
    assert maxon.velocity == pytest.approx(50 * 60 / (2 * math.pi)) and maxon.velocity_unit == "rev/min"
    assert maxon.acceleration == pytest.approx(50 * 60 / (2 * math.pi)) and maxon.accel_unit == "rpm/s"
    assert maxon.position == pytest.approx(4096 * 50 / (2 * math.pi))  # (no factor group: increments)
    zeroerr = declared_units(spec.units(100.0), read_dictionary(EDS / "zeroerr_eDriver-V1.5.eds", 1))
    assert zeroerr.velocity == pytest.approx(4096 * 50 / (2 * math.pi))  # increments per second
    assert zeroerr.motor_speed == pytest.approx(50 * 60 / (2 * math.pi))  # 0x6080: rpm, the profile's unit
    # the ratio the old master wrote 0x6080 in (counts/s for rpm): 68× too loose on a 4096-count encoder
    assert zeroerr.velocity / zeroerr.motor_speed == pytest.approx(4096 / 60)


VALIDATE = [
    ("SIMULATED_ros2canopen_cia402_slave.eds", {}, "backend.drives.0",
     "does not support cyclic synchronous torque (0x6502 = 0x000000A5, bit 9 clear; it has csp)"),
    ("SIMULATED_ros2canopen_cia402_slave.eds", {"mode": "csp"}, None, None),
    ("faulhaber_MCLM300x-CO.eds", {}, "backend.drives.0",
     "it has no cyclic synchronous mode at all); a drive without any cannot be driven cycle by cycle"),
    ("elmo_Gold-Drive.dcf", {}, None, None),
    ("maxon_EPOS4-Module-50-5.eds", {}, None, None),
    ("nanotec_C5-E-2-09.eds", {}, None, None),
    ("zeroerr_eDriver-V1.5.eds", {}, None, None),
]


@pytest.mark.parametrize("name, spec, where, says", VALIDATE, ids=[f"{v[0]}{'-' + v[1]['mode'] if v[1] else ''}"
                                                                 for v in VALIDATE])
def test_validate_on_six_drives_of_each_file(tmp_path, name, spec, where, says):
    diag = _validate(tmp_path, {"drives": _six(name, **spec)})
    if says is None:
        assert diag is None, diag.message
    else:
        assert diag.path == where and says in diag.message, diag.message


def test_a_dcf_for_node_1_given_to_node_2_is_refused_for_its_cob_ids(tmp_path):
    drives = [{"node_id": k} for k in range(1, 7)]
    drives[1]["eds"] = str(EDS / "maxon_EPOS4-Module-50-15_node1.dcf")
    diag = _validate(tmp_path, {"drives": drives})
    assert diag.path == "backend.drives.1.eds"
    # commissioned for node 1 (the DCF's line 54: NodeID=1), given to node 2
    assert _refused(tmp_path, {"drives": drives}).data == {"commissioned": (1, 54), "node_id": 2}
    assert diag.fix == "give this drive node_id: 1, or commission a DCF for node 2"
    text = (EDS / "maxon_EPOS4-Module-50-15_node1.dcf").read_text("latin-1").replace("NodeID=1\n", "NodeID=2\n")
    (tmp_path / "uncommissioned.dcf").write_text(text, "latin-1")  # (said to be node 2's: its COB-IDs are still 1's)
    drives[1]["eds"] = str(tmp_path / "uncommissioned.dcf")
    diag = _validate(tmp_path, {"drives": drives})
    assert diag.path == "backend.drives.1.eds"
    shared = _refused(tmp_path, {"drives": drives}).data  # (node 2's PDO has node 1's RPDO1's COB-ID)
    assert (shared["cob_id"], shared["node"], shared["other_node"], shared["other_pdo"]) == (0x201, 2, 1, "RPDO1")


def test_the_drives_own_pdos_count_in_the_bus_load_and_the_fix_is_named(tmp_path):
    """Nanotec's TPDO3 and TPDO4 stay enabled (asynchronous, no event timer: at worst every cycle): at 500 Hz six
    of them do not fit; ``other_pdos: disable`` turns them off and the same rate fits."""
    diag = _validate(tmp_path, {"drives": _six("nanotec_C5-E-2-09.eds")}, rate=500)
    assert diag.path == "rates.control_hz"
    assert "backend.other_pdos: disable" in diag.fix  # (named only when the drives' own PDOs count)
    assert _validate(tmp_path, {"drives": _six("nanotec_C5-E-2-09.eds"), "other_pdos": "disable"}, rate=500) is None


RUNS = [  # (file, mode, what the run must show): six drives of each, HIT's first 3 s on a lock-step bus
    ("elmo_Gold-Drive.dcf", "cst", 0.02), ("maxon_EPOS4-Module-50-5.eds", "cst", 0.2),
    ("nanotec_C5-E-2-09.eds", "cst", 0.2), ("zeroerr_eDriver-V1.5.eds", "cst", 0.02),
    ("SIMULATED_ros2canopen_cia402_slave.eds", "csp", 0.7),
]


@pytest.fixture(scope="module")
def mujoco_hit():
    from rehabkit.api import run_scenario

    return {rate: run_scenario(HIT, {"rates": {"control_hz": rate}, "duration": 3.0}) for rate in (250, 500)}


@pytest.mark.parametrize("name, mode, within", RUNS, ids=[r[0] for r in RUNS])
def test_hit_runs_on_six_drives_of_each_file_and_tracks_mujoco(tmp_path, mujoco_hit, name, mode, within):
    """The simulated drives serve the vendor's own dictionary (its PDOs, limits, units: maxon's and Nanotec's
    velocities in whole rpm, so their tracking is coarser); the master sets each up from what it reads. Elmo's EDS
    caps 0x1016 sub 1 at 65535, below any consumer entry: said, the SYNC watchdog left to notice a silent host. The
    fake slave has no torque offset: said, its own position loop's integral holds the arm's weight."""
    from rehabkit.api import run_scenario
    from rehabkit.core.safety.estop import own_state

    rate = 500 if mode == "cst" else 250
    drives = [{"node_id": k, "eds": str(EDS / name), "mode": mode} for k in range(1, 7)]
    with own_state(tmp_path / "state"):
        r = run_scenario(HIT, {"rates": {"control_hz": rate}, "duration": 3.0, "expect.task_complete": {"eq": 0},
                               "backend": {
            "type": "canopen", "clock": "lockstep", "drives": drives, "other_pdos": "disable"}}, out_dir=tmp_path)
    m, notes = r.metrics, [n["text"] for n in r.summary["notes"]]
    assert m["safety_events"] == 0 and m["can_emcy"] == 0 and m["can_missed_tpdos"] == 0
    assert r.passed, [e for e in r.summary["expectations"] if not e["passed"]]
    deviation = float(np.degrees(np.abs(mujoco_hit[rate].trace.q - r.trace.q)).max())
    assert deviation < within
    if name.startswith("elmo"):
        assert sum("does not take the host's heartbeat to watch" in n for n in notes) == 6
    if mode == "csp":
        assert sum("no torque offset to map (0x60B2)" in n for n in notes) == 6
    tail = [f for f in can.LogReader(tmp_path / "can.asc")][-12:]
    assert [bytes(f.data) for f in tail if f.arbitration_id == 0][-6:] == [bytes([0x80, k]) for k in range(1, 7)]


def _fixed_tpdos(tmp_path, entries: dict[int, list[int]]) -> Path:
    """The generic servo's EDS with TPDO1 and TPDO2's maps fixed (read-only) to ``entries`` (sub → value)."""
    import re

    text = (ROOT / "rehabkit" / "canopen" / "eds" / "cia402_servo.eds").read_text()
    for k, values in entries.items():
        mapping = f"1A0{k - 1}"
        for sub in range(9):
            value = len(values) if sub == 0 else (values[sub - 1] if sub <= len(values) else 0)
            text = re.sub(rf"(\[{mapping}sub{sub}\][^\[]*?)AccessType=rw([^\[]*?)DefaultValue=\S+",
                          rf"\g<1>AccessType=ro\g<2>DefaultValue={value:#x}", text)
    path = tmp_path / "fixed.eds"
    path.write_text(text)
    return path


def test_a_fixed_mapping_is_used_as_it_is_when_it_carries_what_the_run_needs(tmp_path):
    """TPDO1 fixed to (statusword, position), TPDO2 to (velocity, torque actual): both used as the drive has them,
    the torque actual decoded and not asked for."""
    path = _fixed_tpdos(tmp_path, {1: [0x60410010, 0x60640020], 2: [0x606C0020, 0x60770010]})
    d = read_dictionary(path, 2)
    assert not d.tpdos[0].configurable and d.tpdos[0].entries == ((0x6041, 0, 16), (0x6064, 0, 32))
    plan = plan_pdos(d, 2, *needed(d, "cst"))
    assert [(p.slot.name, p.configure, len(p.entries)) for p in plan.tx] == [("TPDO1", False, 2), ("TPDO2", False, 2)]


def test_a_fixed_mapping_without_what_the_run_needs_is_refused_at_the_drives_file(tmp_path):
    """Every TPDO fixed, none with the velocity: refused by validate, naming the object and the drive's PDOs."""
    path = _fixed_tpdos(tmp_path, {k: [0x60410010] for k in (1, 2, 3, 4)})
    drives = [{"node_id": k} for k in range(1, 7)]
    drives[2]["eds"] = str(path)
    diag = _validate(tmp_path, {"drives": drives})
    assert diag.path == "backend.drives.2.eds"
    d = read_dictionary(path, 3)
    with pytest.raises(PdoPlanError) as refused:  # the objects left without a TPDO, none of them configurable
        plan_pdos(d, 3, *needed(d, "cst"))
    assert refused.value.index == 0x6064 and not any(s.configurable for s in d.tpdos)
    line = path.read_text().splitlines().index("[1A00]") + 1  # (the drive's TPDO mappings, where they begin)
    assert (refused.value.objects, refused.value.where) == ((0x6064, 0x606C), f"fixed.eds:{line}")
