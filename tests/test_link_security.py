"""The authenticated robot link: keys, the session's seal and anti-replay window, the handshake, and the HIT round trip
attacked from a second process while it runs (tests/link_attacker.py): nothing from the attacker is applied."""

import json
import os
import select
import shutil
import signal
import socket
import stat
import subprocess
import sys
import time

import numpy as np
import pytest

from rehabkit.api import run_scenario
from rehabkit.core.setup.errors import SetupError
from rehabkit.hardware.config import LinkKeyError
from rehabkit.hardware.link.protocol import (
    CLEAR,
    COMMAND,
    ESTOPPED,
    HEADER,
    NO_RIGHT,
    Receiver,
    encode,
    pack,
    pack_bytes,
)
from rehabkit.hardware.security.gate import LIVE_S, BridgeGate
from rehabkit.hardware.security.handshake import (
    BUSY,
    NO_KEY,
    OTHER_KEY,
    HostHandshake,
    LinkRefusedError,
    handshake,
)
from rehabkit.hardware.security.keys import KeyFileError, check_robot, load_key, new_key
from rehabkit.hardware.security.session import ReplayWindow
from tests.conftest import ROOT, SCENARIOS
from tests.located import located
from tests.test_cli import cli
from tests.test_hardware_link import QUICK_TRIP

HIT = SCENARIOS / "hit_roundtrip.yaml"
HOST, BRIDGE = ("127.0.0.1", 40001), ("127.0.0.1", 40002)


@pytest.fixture
def key(tmp_path):
    return new_key("hit-1", tmp_path / "hit-1.key")


def _shake(key, gate: BridgeGate, robot: int = 1, host_key=None, addr=HOST, now: float = 0.0):
    """A handshake in process: host → gate → host → gate → host (from ``addr``, at ``now``); the host's session (or
    None) and the host's end."""
    host = HostHandshake(host_key or key, robot)
    seq = iter(range(1, 100))
    session = None
    for _ in range(2):
        reply, _why = gate.reply(host.next(next(seq)), addr, now)
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
    key.path.chmod(0o600)
    made = new_key("hit-1", tmp_path / "keys" / "hit-1.key")  # a keys/ folder made for it: its owner's only
    assert stat.S_IMODE(made.path.parent.stat().st_mode) == 0o700
    made.path.parent.chmod(0o770)  # (others may write the folder: they could swap the key)
    with pytest.raises(KeyFileError) as open_folder:
        load_key(made.path)
    assert (open_folder.value.path, open_folder.value.fix) == (str(made.path), f"chmod go-w {made.path.parent}")
    made.path.parent.chmod(0o700)
    link = tmp_path / "keys" / "link.key"
    link.symlink_to(made.path)
    with pytest.raises(KeyFileError) as symlink:  # (read with O_NOFOLLOW: a link could be pointed anywhere)
        load_key(link)
    assert (symlink.value.path, symlink.value.kind) == (str(link), "symlink")
    with pytest.raises(KeyFileError) as written:  # (nor written through one)
        new_key("hit-1", link, replace=True)
    assert written.value.kind == "symlink"
    os.chown(made.path, 1234, -1)  # (another user's file: as root the test can give it away)
    with pytest.raises(KeyFileError) as theirs:
        load_key(made.path)
    assert (theirs.value.kind, theirs.value.owner) == ("owner", 1234)
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


def test_the_handshake_refuses_another_key_and_a_replayed_proof_and_no_other_host_takes_a_live_session(key, tmp_path):
    gate = BridgeGate(key, 1)
    other = new_key("hit-1", tmp_path / "other.key")
    session, host = _shake(key, gate, host_key=other)
    assert session is None and host.refusal == OTHER_KEY and gate.session is None  # (told; no key id)
    first, host = _shake(key, gate)
    proof = host.next(99)
    assert gate.reply(proof, HOST, 0.0)[1] == "proof-again"  # (its WELCOME lost: the same one again, nothing new)
    assert gate.session.id == first.id
    elsewhere = ("127.0.0.1", 40003)
    assert _shake(key, gate, addr=elsewhere, now=0.5)[0] is None and gate.session.id == first.id  # live: not taken
    second, _ = _shake(key, gate, addr=elsewhere, now=0.5 + LIVE_S)  # (its host silent for LIVE_S: the next may)
    assert second.id != first.id and gate.session.id == second.id and gate.peer == elsewhere
    assert gate.open(encode(COMMAND, 1, 50, np.zeros(3), link=first), HOST) == (None, "other-address")
    at = 0.5 + LIVE_S
    assert _shake(key, gate, addr=HOST, now=at)[1].refusal == BUSY  # live again (just made): HOST's turn is over
    gate.allow(at)  # the person at the bridge lets a new host in (the keypad's a): once
    third, _ = _shake(key, gate, addr=HOST, now=at)
    assert gate.session.id == third.id and _shake(key, gate, addr=elsewhere, now=at)[1].refusal == BUSY
    assert _shake(key, BridgeGate(None, 1))[1].refusal == NO_KEY


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


def _over(port, key, **backend):
    # (the quick round trip, A → B → A in 2.5 s of the link's time: an attack needs the session, not the whole task)
    return run_scenario(HIT, {"backend": {"type": "hardware", "clock": "lockstep", "spawn_bridge": False,
                                          "port": port, "key_file": str(key.path), **backend}, **QUICK_TRIP})


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
            # (the first only captured: the earlier session replayed); each re-keyed every second of the link's time
            runs = [_over(port, key, rekey_s=1.0) for _ in range(2)]
            assert select.select([attacker.stdout], [], [], 30)[0] and attacker.stdout.readline() == "attacker: done\n"
        finally:
            _stop(attacker, signal.SIGTERM)
    finally:
        _stop(bridge)
    clean, attacked = runs
    assert np.array_equal(attacked.trace.q, clean.trace.q) and np.array_equal(attacked.trace.tau, clean.trace.tau)
    assert attacked.summary["safety"]["events"] == [] and attacked.metrics["link_ticks"] == 2500
    report = json.loads((tmp_path / "attack.json").read_text())
    assert "done" in report and report["flood"]["sent"] > 10_000 and report["replayed"]["sent"] == 60
    stats = json.loads((tmp_path / "bridge.json").read_text())
    (host_at,) = stats["opened_from"]  # one address let in: the host's (through the relay)
    assert [(s["from"], s["key_id"]) for s in stats["sessions"]] == [(host_at, key.id)] * 2
    dropped = stats["dropped"]
    assert stats["rekeys"] == 2 * 2  # (2.5 s of the link's time each: re-keyed after 1 s and 2 s, unbroken)
    # what came from the attacker's own address (forged, replayed, the flood) was refused before anything was
    # decrypted; replayed HELLOs and PROOFs made no challenge; what it tampered with in flight failed to open
    for reason in ("other-address", "authentication", "handshake-other-key", "handshake-replayed-hello",
                   "handshake-stale-proof"):
        assert dropped.get(reason, 0) > 0, json.dumps(dropped)
    m = attacked.metrics
    assert m["states_dropped_other_address"] >= 60 and m["states_dropped_authentication"] > 0


def test_a_bridge_beyond_loopback_needs_a_key():
    from rehabkit.cli import exits

    out = cli("bridge", "hit", "--listen", "0.0.0.0:0")
    assert out.returncode == 2 and exits.last_refusal.code == "listen-needs-key"
    assert exits.last_refusal.option == "--listen"


def test_a_latched_estop_is_cleared_over_the_link_only_in_a_session_and_with_a_name(key, tmp_path):
    from rehabkit.cli.estop import ClearRefusedError, clear_over_link
    from rehabkit.core.safety.estop import EStopLatch

    latch = EStopLatch.for_robot("hit", 1, tmp_path / "hit-1.json")
    latch.press("e-stop at the robot", "robot")
    security = tmp_path / "security.jsonl"
    bridge, port = _start([sys.executable, "-m", "rehabkit.cli", "bridge", "hit", "--key", str(key.path),
                           "--latch-file", str(latch.path), "--stats", str(tmp_path / "stats.json"),
                           "--security-log", str(security)], "bridge:")
    try:
        with pytest.raises(ClearRefusedError) as keyless:  # a clear without the key: refused, and said
            clear_over_link("127.0.0.1", port, 1, "mallory", timeout=0.5)
        assert (keyless.value.reason, keyless.value.bridge) == ("key-needed", f"udp://127.0.0.1:{port}")
        # and written to the security log as it happened (the bridge still runs), rate-limited: 10 a second
        logged = [json.loads(line) for line in security.read_text().splitlines()]
        assert 1 <= len(logged) <= 10 + 5 and {(r["reason"], r["source"].split(":")[0]) for r in logged
                                                if "reason" in r} == {("unauthenticated", "127.0.0.1")}
        assert latch.latched() is not None
        clear_over_link("127.0.0.1", port, 1, "Dr. Ana Ruiz", key_file=str(key.path))
        # its session's host said BYE: the bridge serves the next one at once
        assert not clear_over_link("127.0.0.1", port, 1, "Dr. Ana Ruiz", key_file=str(key.path)) & ESTOPPED
        # the key rotated and the bridge told (SIGHUP): a session under the old key ends, the old key is refused
        old = tmp_path / "old.key"
        shutil.copy(key.path, old)
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        seq = iter(range(1, 1000))
        held = handshake(sock, ("127.0.0.1", port), key, 1, lambda: next(seq))  # (live, never ended by its host)
        new = new_key("hit-1", key.path, replace=True)
        bridge.send_signal(signal.SIGHUP)
        until = time.monotonic() + 5.0  # (polled: the bridge reads the file again at its loop's next turn)
        while True:
            try:
                clear_over_link("127.0.0.1", port, 1, "Dr. Ana Ruiz", key_file=str(key.path))
                break
            except LinkRefusedError as exc:
                assert exc.reason == "other-key" and time.monotonic() < until
        sock.sendto(held.seal(pack_bytes(CLEAR, 1, next(seq), b"mallory in the old session", held.id)),
                    ("127.0.0.1", port))  # (read before the next HELLO: the same socket's queue at the bridge)
        sock.close()
        with pytest.raises(LinkRefusedError) as refused:
            clear_over_link("127.0.0.1", port, 1, "Dr. Ana Ruiz", key_file=str(old))
        assert (refused.value.reason, refused.value.key_id) == ("other-key", key.id)
        assert bridge.poll() is None
    finally:
        _stop(bridge)
    stats = json.loads((tmp_path / "stats.json").read_text())
    assert [s["key_id"] for s in stats["sessions"]] == [key.id] * 3 + [new.id]
    assert (stats["key_id"], stats["clear_key_id"]) == (new.id, None)  # (the bridge's own, as rotated)
    record = json.loads(latch.path.read_text())
    assert not record["latched"] and record["cleared_by"] == "Dr. Ana Ruiz" and record["key_id"] == key.id
    clears = stats["estop_clears"]  # the bridge's own record of them
    assert [(c["by"], c["latched"], c["key_id"]) for c in clears] == [("Dr. Ana Ruiz", True, key.id)] + \
        [("Dr. Ana Ruiz", False, key.id)] * (len(clears) - 2) + [("Dr. Ana Ruiz", False, new.id)]
    # (the old session's CLEAR: ended, not applied; refused as another session's, or from another address while the
    # next clear's session was still open)
    assert stats["dropped"].get("other-session", 0) + stats["dropped"].get("other-address", 0) >= 1
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
        # (and the quick round trip, 2.5 s of the link's time rather than 8.5: what is asserted is the commands, the
        # session and its key, not the task's length)
        quick: dict = {}
        for dotted, value in QUICK_TRIP.items():
            *heads, last = dotted.split(".")
            at = quick
            for head in heads:
                at = at.setdefault(head, {})
            at[last] = value
        lab += "".join(f"{k}: {json.dumps(v)}\n" for k, v in quick.items())
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
        assert keyless.returncode == 2 and not (tmp_path / "keyless" / "summary.json").exists()
        said = refused_by_link(tmp_path / "keyless.yaml")  # what it says: the bridge needs a key, and where to set it
        assert (said.bridge, said.reason, said.key_file, said.key_id) == (f"udp://127.0.0.1:{port}", "key-needed",
                                                                         None, None)
        assert said.fix == "set backend.key_file to the robot's key file (the one the bridge was given)"
        rotated = run("rehabkit keys new hit-1 --out keys/hit-1.key --replace")
        new = load_key(tmp_path / "keys" / "hit-1.key")
        assert rotated.returncode == 0 and new.id != key.id
        refused = run(run_cmd)  # the bridge still holds the old key: the host is told, with its key's id and file
        assert refused.returncode == 2 and key.id not in refused.stderr  # (a refusal names no key id of the bridge's)
        said = refused_by_link(tmp_path / "lab_hit.yaml")
        assert (said.reason, said.key_id, said.key_file) == ("other-key", new.id, str(tmp_path / "keys" / "hit-1.key"))
    finally:
        _stop(bridge)
    assert json.loads((tmp_path / "stats.json").read_text())["dropped"]["unauthenticated"] > 0


def refused_by_link(scenario) -> LinkKeyError:
    """The :class:`LinkKeyError` a run of ``scenario`` is refused with, in this process (the refusal `rehabkit run`
    says, as fields)."""
    with pytest.raises(SetupError) as refused:  # (the backend's fault as the session opens: a setup error, exit 2)
        run_scenario(scenario)
    assert isinstance(refused.value.__cause__, LinkKeyError), refused.value
    return refused.value.__cause__


def test_a_urdf_robot_runs_over_an_authenticated_link_and_validate_checks_its_key_file(tmp_path, monkeypatch):
    """A robot that is not built in (the README's URDF arm, its file beside its scenario) over the link with a key
    (the spawned bridge finds the URDF where the host does); a missing or open key file is refused by ``validate``,
    at the scenario's line, before anything runs."""
    scenario = tmp_path / "lab_arm4.yaml"
    # (its plan ends at 6.7 s: run to 7.0, not the example's 12, each tick a round trip to the bridge; in simulation
    # its final error is then 6e-8 m against the example's 2 mm, its tracking as at 12 s)
    scenario.write_text(f"extends: {ROOT}/examples/robots/urdf_arm4.yaml\n"
                        "backend: {type: hardware, clock: lockstep, key_file: keys/arm4.key}\nduration: 7.0\n")
    missing = cli("validate", scenario)
    # (the key file's own error, its fix: test_a_key_file_is_owner_only_named_for_its_robot_and_never_shows_its_secret)
    assert missing.returncode == 2 and located(missing.stderr) == [(str(scenario), 2, 44, "backend.key_file")]
    key = new_key("arm4-1", tmp_path / "keys" / "arm4.key")
    key.path.chmod(0o640)
    assert located(cli("validate", scenario).stderr) == [(str(scenario), 2, 44, "backend.key_file")]
    key.path.chmod(0o600)
    assert cli("validate", scenario).returncode == 0
    beyond = tmp_path / "beyond.yaml"  # a bridge on another computer, and no key: refused at the host's line
    beyond.write_text(f"extends: {ROOT}/examples/robots/urdf_arm4.yaml\n"
                      "backend: {type: hardware, spawn_bridge: false, host: 192.168.1.20, port: 7000}\n")
    refused = cli("validate", beyond)
    assert refused.returncode == 2 and located(refused.stderr) == [(str(beyond), 2, 48, "backend.host")]
    run = run_scenario(scenario)
    assert run.passed and run.summary["notes"][0]["text"].endswith(f"key {key.id}")
    assert run.metrics["states_dropped"] == 0 and run.metrics["safety_events"] == 0


def test_clearing_is_a_right_of_its_own_and_every_clear_is_kept_with_its_session_and_key(hit, key, tmp_path):
    """A bridge given a clearing key takes a clear only in a session under it (which drives nothing); one declared
    keypad-only takes none over the link; every clear is appended to the latch's history with the session and key
    ids, none rewritten."""
    from rehabkit.core.safety.estop import EStopLatch
    from rehabkit.hardware.bridge import Bridge
    from rehabkit.hardware.keypad import handle
    from rehabkit.hardware.plant import MujocoPlant

    clearing_key = new_key("hit-1", tmp_path / "clear.key")
    latch = EStopLatch.for_robot("hit", 1, tmp_path / "hit-1.json")
    latch.press("e-stop at the robot", "robot")
    bridge = Bridge(MujocoPlant(hit), key=key, clear_key=clearing_key, latch=latch)
    gate = bridge.link.gate

    def clear(by: str, session) -> None:
        bridge.receive(0.0, [(pack_bytes(CLEAR, 1, 5, by.encode(), session.id), HOST)])

    driving, _ = _shake(key, gate)
    clear("Dr. Ana Ruiz", driving)  # the robot's key drives; it does not clear
    assert latch.latched() is not None and bridge.status & NO_RIGHT and bridge.rx.dropped["clear-right"] == 1
    gate.end()  # (its host's BYE)
    clearing, _ = _shake(clearing_key, gate)
    bridge.receive(0.0, [(pack(COMMAND, 1, 6, np.ones(6), session=clearing.id), HOST)])
    assert bridge.rx.dropped["clear-only"] == 1 and bridge.rx.accepted == 0  # (a clearing session drives nothing)
    clear("Dr. Ana Ruiz", clearing)
    clear("J. Doe", clearing)
    assert latch.latched() is None and not bridge.status & NO_RIGHT
    history = [(c["cleared_by"], c["was_latched"], c["session"], c["key_id"]) for c in latch.cleared()]
    assert history == [("Dr. Ana Ruiz", True, f"{clearing.id:08x}", clearing_key.id),
                       ("J. Doe", False, f"{clearing.id:08x}", clearing_key.id)]
    keypad_only = Bridge(MujocoPlant(hit), key=key, latch=latch, clear_right="keypad")
    latch.press("e-stop at the robot", "robot")
    session, _ = _shake(key, keypad_only.link.gate)
    keypad_only.receive(0.0, [(pack_bytes(CLEAR, 1, 5, b"Dr. Ana Ruiz", session.id), HOST)])
    assert latch.latched() is not None and keypad_only.rx.dropped["clear-right"] == 1
    handle(keypad_only, ["clear"], 0.0)
    assert latch.latched() is None and latch.cleared()[-1]["cleared_by"] == "the keypad at the robot"


def test_refused_attempts_are_logged_as_they_happen_at_most_ten_a_second(tmp_path):
    """At most 10 lines in each second of the wall clock, the summing-up of a flood included (a token bucket let
    15-19 into one second)."""
    from collections import Counter

    from rehabkit.hardware.security.events import PER_S, SecurityLog

    log = SecurityLog(tmp_path / "security" / "hit-1.jsonl")
    t0 = 1_800_000_000.5  # (the wall clock's time: half a second into a second)
    for i in range(2500):  # a flood: 1000 refusals a second for 2.5 s, over three seconds of the wall clock
        log.refused(("10.0.0.9", 4000 + i % 3), "unauthenticated" if i % 2 else "handshake-other-key",
                    now=t0 + i * 1e-3)
    lines = [json.loads(line) for line in log.path.read_text().splitlines()]  # (written already: as they happened)
    assert (lines[0]["source"], lines[0]["reason"], lines[0]["at"]) == ("10.0.0.9:4000", "handshake-other-key",
                                                                        "2027-01-15T08:00:00.500+00:00")
    log.close()  # (the rest summed up in the newest line's second: a line of each was kept for it)
    lines = [json.loads(line) for line in log.path.read_text().splitlines()]
    per_second = Counter(line["at"][:19] for line in lines)
    assert sorted(per_second.values()) == [9, 9, 10] and max(per_second.values()) <= PER_S
    summaries = [line for line in lines if "suppressed" in line]
    refusals = [line for line in lines if "reason" in line]
    assert len(summaries) == 3 and sum(s["suppressed"] for s in summaries) + len(refusals) == 2500
    assert all(sum(s["by_reason"].values()) == s["suppressed"] for s in summaries) and "suppressed" in lines[-1]
    assert stat.S_IMODE(log.path.stat().st_mode) == 0o600


def _host(bridge, key):
    """A host's end of the link to ``bridge`` in this process, its session made by hand (the bridge's end pumped:
    ``arrived``; loopback delivers a datagram before ``sendto`` returns), and what else the bridge read meanwhile."""
    from rehabkit.hardware.link.clock import wait_readable
    from rehabkit.hardware.link.host_end import HostLink
    from rehabkit.hardware.link.protocol import STATE

    wire = HostLink("127.0.0.1", bridge.port, 1, key, Receiver(STATE, 1, 6), 0.001)
    shake, read = HostHandshake(key, 1), []
    for _ in range(2):  # HELLO → CHALLENGE, PROOF → WELCOME
        wire.sock.sendto(shake.next(wire.next_seq()), wire.addr)
        read += bridge.link.arrived()
        assert wait_readable(wire.sock, 1.0)
        session = shake.take(wire.sock.recv(65536))
    wire.link, wire.first_id = session, session.id
    return wire, read


def test_a_session_taken_over_at_the_keypad_is_the_new_hosts_and_the_old_host_is_told(hit, key):
    """After the keypad's a, a second host's session takes the robot over: its reset starts its run (a command of the
    first host's read before the takeover, taken after it, set the sequence count back: every command of the new
    host's was then out of order, "does not answer a reset"); the first host is told, in its own session, that it
    was taken over at the keypad, and its run stops saying so (it stopped on "no valid state" after 100 ms)."""
    from types import SimpleNamespace

    from rehabkit.hardware.backend import HardwareBackend
    from rehabkit.hardware.bridge import Bridge
    from rehabkit.hardware.config import SessionTakenOverError
    from rehabkit.hardware.keypad import handle
    from rehabkit.hardware.link.protocol import CMD_RESET, ENABLED, HOLDING
    from rehabkit.hardware.plant import MujocoPlant

    q0 = np.radians([0.0, 90.0, 90.0, 30.0, -90.0, 90.0])
    bridge = Bridge(MujocoPlant(hit), key=key, watchdog_s=1.0)
    first = second = None
    try:
        first, _ = _host(bridge, key)
        first.send(COMMAND, q0, 0.0, CMD_RESET)
        for k in range(1, 6):  # its run: a command a tick
            bridge.tick(k * 1e-3, bridge.link.arrived())
            first.send(COMMAND, bridge.plant.gravity(q0), k * 1e-3)
            assert len(first.arrived(lambda: 0.0, False)) == 1  # (its state)
        handle(bridge, ["allow"], 0.006)  # the person at the robot: a (the first host's run still live)
        second, read = _host(bridge, key)  # (its PROOF read after a command of the first host's: one tick's inbox)
        bridge.tick(0.006, read)
        second.send(COMMAND, q0, 0.0, CMD_RESET)
        first.send(COMMAND, bridge.plant.gravity(q0), 0.007)  # (refused: its session has ended)
        bridge.tick(0.007, bridge.link.arrived())
        states = [HEADER.unpack_from(p)[9] for p, _ in second.arrived(lambda: 0.0, False)]
        assert states and states[-1] & ENABLED and not states[-1] & HOLDING
        assert bridge.rx.dropped["ended-session"] == 1 and bridge.rx.dropped["out-of-order"] == 0
        assert first.arrived(lambda: 0.0, False) == [] and first.ended == "keypad"
        with pytest.raises(SessionTakenOverError) as taken:  # (how the run's backend stops on it)
            HardwareBackend._taken_over(SimpleNamespace(wire=first))
        assert (taken.value.bridge, taken.value.allowed) == (first.where, "keypad")
        assert [s["session"] for s in bridge.link.stats()["sessions"]] == [f"{w.link.id:08x}" for w in (first, second)]
    finally:
        for wire in (first, second):
            if wire is not None:
                wire.sock.close()
        bridge.link.close()


def test_a_host_refused_for_another_hosts_live_session_is_told_of_the_session_not_of_keys(key, monkeypatch):
    """The keys match: the refusal says the bridge serves another host's live session and how a new one gets in (it
    ended in "give both ends the same key file")."""
    from rehabkit.hardware.config import LinkBusyError
    from rehabkit.hardware.link import host_end
    from rehabkit.hardware.security.handshake import refusal_words

    def busy(*args, **kwargs):
        raise LinkRefusedError("busy", key.id, refusal_words(BUSY, key))

    monkeypatch.setattr(host_end, "handshake", busy)
    wire = host_end.HostLink("127.0.0.1", 7000, 1, key, Receiver(COMMAND, 1, 6), 0.001)
    with pytest.raises(LinkBusyError) as refused:
        wire.open_session()
    wire.close()
    assert (refused.value.bridge, refused.value.problem) == ("udp://127.0.0.1:7000", refusal_words(BUSY, key))
