"""The authenticated robot link: keys, the session's seal and anti-replay window, the handshake, and the HIT round trip
attacked from a second process while it runs (tests/link_attacker.py): nothing from the attacker is applied."""

import json
import os
import select
import signal
import stat
import subprocess
import sys

import numpy as np
import pytest

from rehabkit.api import run_scenario
from rehabkit.hardware.link.protocol import COMMAND, ESTOPPED, HEADER, Receiver, encode
from rehabkit.hardware.security.handshake import BridgeGate, HostHandshake
from rehabkit.hardware.security.keys import KeyFileError, check_robot, load_key, new_key
from rehabkit.hardware.security.session import ReplayWindow
from tests.conftest import ROOT, SCENARIOS
from tests.located import located
from tests.test_cli import cli

HIT = SCENARIOS / "hit_roundtrip.yaml"
HOST, BRIDGE = ("127.0.0.1", 40001), ("127.0.0.1", 40002)


@pytest.fixture
def key(tmp_path):
    return new_key("hit-1", tmp_path / "hit-1.key")


def _shake(key, gate: BridgeGate, robot: int = 1, host_key=None):
    """A handshake in process: host → gate → host → gate → host; the host's session (or None) and the gate's."""
    host = HostHandshake(host_key or key, robot)
    seq = iter(range(1, 100))
    for _ in range(2):
        reply, _why = gate.reply(host.next(next(seq)), HOST)
        session = host.take(reply) if reply is not None else None
    return session, host


def test_a_key_file_is_owner_only_named_for_its_robot_and_never_shows_its_secret(key, tmp_path):
    assert stat.S_IMODE(key.path.stat().st_mode) == 0o600
    text = key.path.read_text()
    fields = {k: v for k, _, v in (line.partition(": ") for line in text.splitlines()[1:])}  # (after its headline)
    assert (fields["id"], fields["robot"]) == (key.id, "hit-1")
    assert key.secret.hex() not in repr(key) + str(key)  # (a key printed in a log says its id, not its secret)
    assert load_key(key.path) == key
    with pytest.raises(KeyFileError) as exists:  # a rotation is deliberate: the file there is kept
        new_key("hit-1", key.path)
    assert exists.value.path == str(key.path) and load_key(key.path) == key
    assert new_key("hit-1", key.path, replace=True).id != key.id
    key.path.chmod(0o644)
    with pytest.raises(KeyFileError) as readable:
        load_key(key.path)
    assert (readable.value.path, readable.value.fix) == (str(key.path), f"chmod 600 {key.path}")
    with pytest.raises(KeyFileError) as missing:
        load_key(tmp_path / "none.key")
    assert (missing.value.path, missing.value.fix) == (
        str(tmp_path / "none.key"), "make one with `rehabkit keys new ROBOT-ID --out FILE` and give the same file to "
        "the bridge")
    with pytest.raises(KeyFileError) as other_robot:
        check_robot(key, "lexos-1")
    assert (other_robot.value.path, other_robot.value.fix) == (
        str(key.path), "use lexos-1's key (`rehabkit keys new lexos-1` makes one)")


def test_the_window_takes_each_number_once_and_nothing_older_than_64():
    w = ReplayWindow()
    seen = []
    for seq in (1, 3, 2, 3, 100, 40, 37, 36, 37, 101, 100):
        fresh = w.fresh(seq)
        if fresh:
            w.mark(seq)
        seen.append(fresh)
    assert seen == [True, True, True, False, True, True, True, False, False, True, False]  # 36 < 101 - 64: too old


def test_a_session_opens_what_its_peer_sealed_once_and_nothing_altered(key):
    gate = BridgeGate(key, 1)
    session, _ = _shake(key, gate)
    assert session is not None and gate.session.id == session.id and gate.peer == HOST
    data = encode(COMMAND, 1, 7, np.array([0.5, -1.0, 2.0]), sent_at=1.0, link=session)
    assert data[HEADER.size:-16] != np.array([0.5, -1.0, 2.0]).tobytes()  # the body is encrypted
    for bit in range(8 * len(data)):  # every single-bit change anywhere is refused, and moves nothing
        flipped = bytearray(data)
        flipped[bit // 8] ^= 1 << bit % 8
        plain, why = gate.open(bytes(flipped), HOST)
        assert plain is None and why in {"authentication", "other-session", "unauthenticated", "length"}, (bit, why)
    rx = Receiver(COMMAND, 1, 3)
    plain, _ = gate.open(data, HOST)
    assert rx.take(plain).values.tolist() == [0.5, -1.0, 2.0]
    assert gate.open(data, HOST) == (None, "replayed")
    assert gate.open(encode(COMMAND, 1, 8, np.zeros(3)), HOST) == (None, "unauthenticated")  # a CRC is no key
    assert gate.open(encode(COMMAND, 1, 9, np.zeros(3), link=session), ("127.0.0.1", 9)) == (None, "other-address")
    with pytest.raises(ValueError, match="never repeats"):
        encode(COMMAND, 1, 9, np.zeros(3), link=session)  # (a repeated nonce would give the key away)


def test_the_handshake_refuses_another_key_and_a_replayed_proof_and_a_new_one_ends_the_old_session(key, tmp_path):
    gate = BridgeGate(key, 1)
    other = new_key("hit-1", tmp_path / "other.key")
    session, host = _shake(key, gate, host_key=other)
    assert session is None and host.problem == f"the bridge holds another key (its key id {key.id}, this key's " \
                                               f"{other.id})"
    first, host = _shake(key, gate)
    proof = host.next(99)
    assert gate.reply(proof, HOST) == (None, "stale-proof")  # each nonce proves once
    second, _ = _shake(key, gate)
    assert second.id != first.id and gate.session.id == second.id
    assert gate.open(encode(COMMAND, 1, 50, np.zeros(3), link=first), HOST) == (None, "other-session")
    assert _shake(key, BridgeGate(None, 1))[1].problem == "the bridge has no key (it was started without --key)"


def _start(cmd, prefix, cwd=ROOT):
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=cwd)
    line = proc.stdout.readline()
    assert line.startswith(prefix), line
    return proc, int(line.rsplit(":", 1)[1])


def _bridge(key, stats):
    return _start([sys.executable, "-m", "rehabkit.cli", "bridge", "hit", "--lockstep", "--key", str(key.path),
                   "--stats", str(stats)], "bridge:")


def _stop(proc, sig=signal.SIGINT):
    proc.send_signal(sig)
    proc.wait(10)
    proc.stdout.close()


def _over(port, key):
    return run_scenario(HIT, {"backend": {"type": "hardware", "clock": "lockstep", "spawn_bridge": False,
                                          "port": port, "key_file": str(key.path)}})


def test_an_attacked_round_trip_moves_exactly_as_an_unattacked_one_and_applies_nothing_of_the_attackers(key, tmp_path):
    """A second process on the path forges, replays (this session's datagrams and an earlier one's), tampers (a
    captured datagram, and in flight), tries other keys and floods the bridge for a second; the robot moves as in the
    unattacked run, sample for sample, with no safety event; the bridge let in datagrams from the host's address
    alone, and every drop is counted by reason at both ends. (The full figures: benchmarks/link_attacks.py.)"""
    bridge, port = _bridge(key, tmp_path / "bridge.json")  # one bridge, two sessions (each reset from scratch)
    try:
        attacker, port = _start([sys.executable, str(ROOT / "tests" / "link_attacker.py"), str(port), "--joints", "6",
                                 "--session", "2", "--count", "60", "--flood-s", "0.5",
                                 "--report", str(tmp_path / "attack.json")], "attacker:")
        try:
            runs = [_over(port, key) for _ in range(2)]  # the first only captured: the earlier session replayed
            assert select.select([attacker.stdout], [], [], 30)[0] and attacker.stdout.readline() == "attacker: done\n"
        finally:
            _stop(attacker, signal.SIGTERM)
    finally:
        _stop(bridge)
    clean, attacked = runs
    assert np.array_equal(attacked.trace.q, clean.trace.q) and np.array_equal(attacked.trace.tau, clean.trace.tau)
    assert attacked.summary["safety"]["events"] == [] and attacked.metrics["link_ticks"] == 8500
    report = json.loads((tmp_path / "attack.json").read_text())
    assert "done" in report and report["flood"]["sent"] > 10_000 and report["replayed"]["sent"] == 60
    stats = json.loads((tmp_path / "bridge.json").read_text())
    (host_at,) = stats["opened_from"]  # one address let in: the host's (through the relay)
    assert [(s["from"], s["key_id"]) for s in stats["sessions"]] == [(host_at, key.id)] * 2
    dropped = stats["dropped"]
    for reason in ("unauthenticated", "replayed", "other-session", "handshake-other-key", "handshake-stale-proof"):
        assert dropped[reason] > 0, dropped
    # (the forged torques, resets, clears and clocks that reached it: the flood beside them overflows the socket's
    # buffer, and the kernel drops what does not fit)
    assert 0 < dropped["unauthenticated"] <= 4 * 60
    m = attacked.metrics
    assert m["states_dropped_unauthenticated"] >= 60 and m["states_dropped_replayed"] > 0
    assert m["states_dropped_authentication"] > 0  # (tampered in flight: the host asked again)


def test_a_bridge_beyond_loopback_needs_a_key():
    out = cli("bridge", "hit", "--listen", "0.0.0.0:0")
    assert out.returncode == 2 and "beyond this machine's loopback anyone on the network could drive the robot" in \
        out.stderr and "--key FILE" in out.stderr


def test_a_latched_estop_is_cleared_over_the_link_only_in_a_session_and_with_a_name(key, tmp_path):
    from rehabkit.cli.estop import clear_over_link
    from rehabkit.core.safety.estop import EStopLatch

    latch = EStopLatch.for_robot("hit", 1, tmp_path / "hit-1.json")
    latch.press("e-stop at the robot", "robot")
    bridge, port = _start([sys.executable, "-m", "rehabkit.cli", "bridge", "hit", "--key", str(key.path),
                           "--latch-file", str(latch.path), "--stats", str(tmp_path / "stats.json")], "bridge:")
    try:
        with pytest.raises(PermissionError, match="needs a key"):  # a clear without the key: refused, and said
            clear_over_link("127.0.0.1", port, 1, "mallory", timeout=0.5)
        assert latch.latched() is not None
        clear_over_link("127.0.0.1", port, 1, "Dr. Ana Ruiz", key_file=str(key.path))
        # its session's host gone (the bridge's states to it refused by the OS), the bridge serves the next one
        assert not clear_over_link("127.0.0.1", port, 1, "Dr. Ana Ruiz", key_file=str(key.path)) & ESTOPPED
        assert bridge.poll() is None
    finally:
        _stop(bridge)
    record = json.loads(latch.path.read_text())
    assert not record["latched"] and record["cleared_by"] == "Dr. Ana Ruiz" and record["key_id"] == key.id
    clears = json.loads((tmp_path / "stats.json").read_text())["estop_clears"]  # the bridge's own record of them
    assert [(c["by"], c["latched"], c["key_id"]) for c in clears] == [("Dr. Ana Ruiz", True, key.id)] + \
        [("Dr. Ana Ruiz", False, key.id)] * (len(clears) - 1)
    assert os.stat(latch.path).st_size > 0


def test_the_readmes_lab_network_commands_run_as_written(tmp_path, monkeypatch):
    """The README's "On a lab network" block, run as written at the robot and the host — with this machine's loopback
    standing in for the robot computer's address and the bridge's port its own (7000 may be taken), on the lock-step
    clock (the real-time link is tests/test_hardware_link.py's, authenticated too) — then a host without the key
    and one with the key rotated are refused, each told why (exit 2, the bridge, the key ids, the key file)."""
    import re
    import shlex

    readme = (ROOT / "README.md").read_text()
    section = readme[readme.index("### On a lab network"):]
    commands = [c.split("#")[0].strip() for c in re.search(r"```bash\n(.*?)```", section, re.S)[1].splitlines()]
    scenario = re.search(r"```yaml\n(.*?)```", section, re.S)[1]
    keys_new, bridge_cmd, run_cmd, clear_cmd = commands
    assert run_cmd == "rehabkit run lab_hit.yaml"
    monkeypatch.setenv("REHABKIT_STATE", str(tmp_path / "state"))

    def run(command: str):
        return cli(*shlex.split(command)[1:], cwd=tmp_path)

    made = run(keys_new)
    assert made.returncode == 0 and stat.S_IMODE((tmp_path / "keys" / "hit-1.key").stat().st_mode) == 0o600
    key = load_key(tmp_path / "keys" / "hit-1.key")
    assert key.id in made.stdout and key.secret.hex() not in made.stdout
    bridge, port = _start([sys.executable, "-m", "rehabkit.cli", *shlex.split(bridge_cmd.replace(":7000", ":0"))[1:],
                           "--lockstep", "--stats", str(tmp_path / "stats.json")], "bridge:", cwd=tmp_path)
    try:
        lab = scenario.replace("scenarios/", f"{ROOT}/scenarios/").replace("192.168.1.20", "127.0.0.1") \
            .replace("port: 7000", f"port: {port}").replace("type: hardware,", "type: hardware, clock: lockstep,")
        (tmp_path / "lab_hit.yaml").write_text(lab)
        done = run(run_cmd)
        assert done.returncode == 0, done.stderr
        notes = json.loads((tmp_path / "out" / "lab_hit" / "summary.json").read_text())["notes"]
        assert notes[0]["text"].endswith(f"key {key.id}")
        cleared = run(clear_cmd.replace("192.168.1.20:7000", f"127.0.0.1:{port}"))
        # (the run left nothing latched: the bridge says so, not "cleared")
        assert cleared.returncode == 0 and cleared.stdout == f"hit-1: not latched at the bridge udp://127.0.0.1:" \
            f"{port}\n", cleared.stderr
        (tmp_path / "keyless.yaml").write_text(lab.replace(", key_file: keys/hit-1.key", ""))
        keyless = run("rehabkit run keyless.yaml --out keyless")
        assert keyless.returncode == 2 and f"the bridge at udp://127.0.0.1:{port} refuses this host's session: the " \
            "bridge needs a key (it was started with --key)" in keyless.stderr and "set backend.key_file" in \
            keyless.stderr and not (tmp_path / "keyless" / "summary.json").exists()
        rotated = run("rehabkit keys new hit-1 --out keys/hit-1.key --replace")
        new = load_key(tmp_path / "keys" / "hit-1.key")
        assert rotated.returncode == 0 and new.id != key.id
        refused = run(run_cmd)  # the bridge still holds the old key: the host is told, with both ids and its file
        assert refused.returncode == 2 and f"the bridge holds another key (its key id {key.id}, this key's {new.id})" \
            in refused.stderr and str(tmp_path / "keys" / "hit-1.key") in refused.stderr
    finally:
        _stop(bridge)
    assert json.loads((tmp_path / "stats.json").read_text())["dropped"]["unauthenticated"] > 0


def test_a_urdf_robot_runs_over_an_authenticated_link_and_validate_checks_its_key_file(tmp_path, monkeypatch):
    """A robot that is not built in (the README's URDF arm, its file beside its scenario) over the link with a key
    (the spawned bridge finds the URDF where the host does); a missing or open key file is refused by ``validate``,
    at the scenario's line, before anything runs."""
    scenario = tmp_path / "lab_arm4.yaml"
    scenario.write_text(f"extends: {ROOT}/examples/robots/urdf_arm4.yaml\n"
                        "backend: {type: hardware, clock: lockstep, key_file: keys/arm4.key}\n")
    missing = cli("validate", scenario)
    # (the key file's own error, its fix: test_a_key_file_is_owner_only_named_for_its_robot_and_never_shows_its_secret)
    assert missing.returncode == 2 and located(missing.stderr) == [(str(scenario), 2, 44, "backend.key_file")]
    key = new_key("arm4-1", tmp_path / "keys" / "arm4.key")
    key.path.chmod(0o640)
    assert located(cli("validate", scenario).stderr) == [(str(scenario), 2, 44, "backend.key_file")]
    key.path.chmod(0o600)
    assert cli("validate", scenario).returncode == 0
    run = run_scenario(scenario)
    assert run.passed and run.summary["notes"][0]["text"].endswith(f"key {key.id}")
    assert run.metrics["states_dropped"] == 0 and run.metrics["safety_events"] == 0
