"""The bridge never applies a torque open-loop for long: a gap in the commands is held through, on its own ticks."""

import socket

import numpy as np
import pytest

from rehabkit.hardware.bridge import Bridge
from rehabkit.hardware.bridge_limits import BridgeLimits
from rehabkit.hardware.link.protocol import (
    CMD_COMPLIANT,
    CMD_RESET,
    COMMAND,
    ENABLED,
    HOLDING,
    LIMIT,
    STALE,
    STATE,
    WATCHDOG,
    Receiver,
    encode,
)
from rehabkit.hardware.plant import MujocoPlant

Q0 = np.radians([0.0, 90.0, 90.0, 30.0, -90.0, 90.0])
PUSH = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 1.0])  # on the wrist: alone, it spins the wrist in a few hundred ms


class Host:
    """The host end, by hand: commands out, states in; the bridge ticked on a clock this test sets."""

    def __init__(self, bridge: Bridge):
        self.bridge, self.seq, self.now = bridge, 0, 0.0
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.settimeout(1.0)
        self.rx = Receiver(STATE, 1, bridge.plant.joints)

    def send(self, values: np.ndarray, flags: int = 0) -> None:
        self.seq += 1
        self.sock.sendto(encode(COMMAND, 1, self.seq, values, status=flags), ("127.0.0.1", self.bridge.port))

    def tick(self, advance: bool = True):
        """One bridge tick (the clock moves a period, or stands still as in a bridge catching up); its state."""
        self.now += self.bridge.plant.timestep if advance else 0.0
        self.bridge.tick(self.now)
        msg = self.rx.accept(self.sock.recv(65536))
        return msg.values[0], msg.values[1], msg.values[2], msg.status

    def hold_gravity(self, ticks: int):
        for _ in range(ticks):
            q, qd, *_ = self.state
            self.send(100 * (Q0 - q) - 5 * qd + self.bridge.plant.gravity(q))
            self.state = self.tick()
        return self.state


def _started(hit, stale_s: float) -> Host:
    bridge = Bridge(MujocoPlant(hit), watchdog_s=1.0, stale_s=stale_s)
    host = Host(bridge)
    host.send(Q0, CMD_RESET)
    host.state = host.tick()
    host.hold_gravity(50)
    return host


def _push_then_silence(host: Host, ticks: int, advance: bool = True, flags: int = 0,
                       seen: list | None = None) -> tuple[np.ndarray, list[int]]:
    q, qd, *_ = host.state
    host.send(host.bridge.plant.gravity(q) + PUSH, flags)  # the last command before the host goes quiet
    wrist, status = [], []
    for _ in range(ticks):
        q, qd, tau, st = host.tick(advance)
        wrist.append(q[5])
        status.append(st)
        if seen is not None:
            seen.append((q, qd, tau))
    return np.degrees(np.array(wrist) - Q0[5]), status


@pytest.fixture
def bridges(hit):
    made = []

    def make(stale_s):
        made.append(_started(hit, stale_s))
        return made[-1]

    yield make
    for host in made:
        host.sock.close()
        host.bridge.link.close()


def test_a_gap_in_the_commands_is_held_through_not_pushed_through(bridges):
    held = bridges(0.010)
    wrist, status = _push_then_silence(held, 200)
    assert held.hold_gravity(1)[3] == ENABLED  # not latched: the next command resumes torque control at once
    open_loop = bridges(10.0)  # the old behaviour: the last torque stays on until the watchdog (1 s here)
    wrist_ol, _ = _push_then_silence(open_loop, 200)
    # 10 ms of the push, then the bridge holds where the wrist is (0.3° here); the open-loop push spins it away (60°)
    assert np.abs(wrist).max() < 2.0 and np.abs(wrist_ol).max() > 20 * np.abs(wrist).max()
    stale = [bool(s & STALE) for s in status]
    assert stale.index(True) == 10 and all(stale[10:])  # 10 ticks of the push, then held
    assert not any(s & (HOLDING | WATCHDOG) for s in status) and all(s & ENABLED for s in status)
    assert held.bridge.stale_holds[0][1] == 190 and held.bridge.trips == []


def test_a_gap_while_the_host_yields_is_bridged_without_stiffness(bridges):
    """The host's safety layer yields (CMD_COMPLIANT): the bridge's hold through a gap damps and carries the arm's
    weight but does not pull it back to where the gap began — the person pushing is not resisted."""
    host, seen = bridges(0.010), []
    wrist, status = _push_then_silence(host, 200, flags=CMD_COMPLIANT, seen=seen)
    assert all(s & STALE for s in status[11:]) and host.bridge.compliant
    effort = host.bridge.plant.effort
    for (q, qd, _), (_, _, tau) in zip(seen[11:], seen[12:]):  # applied in the tick after a state: gravity, damping
        np.testing.assert_allclose(tau, np.clip(host.bridge.plant.gravity(q) - 6.0 * qd, -effort, effort), atol=1e-9)
    stiff, seen_stiff = bridges(0.010), []
    _push_then_silence(stiff, 200, seen=seen_stiff)  # without the flag: the posture where the gap began is held
    q_gap = seen_stiff[9][0]  # (read at the start of the tick the gap began in: the state before it)
    (q, qd, _), (_, _, tau) = seen_stiff[50], seen_stiff[51]
    np.testing.assert_allclose(tau, np.clip(60.0 * (q_gap - q) - 6.0 * qd + stiff.bridge.plant.gravity(q), -effort,
                                            effort), atol=1e-9)


def test_a_bridge_catching_up_after_its_own_stall_holds_too(bridges):
    """Ticks, not wall time, count: a bridge ticking through a backlog without new commands holds as well."""
    host = bridges(0.010)
    wrist, status = _push_then_silence(host, 100, advance=False)
    assert all(s & STALE for s in status[11:]) and np.abs(wrist).max() < 2.0


def test_the_watchdog_still_latches_a_hold_after_a_long_silence(hit):
    bridge = Bridge(MujocoPlant(hit), watchdog_s=0.050, stale_s=0.010)
    host = Host(bridge)
    try:
        host.send(Q0, CMD_RESET)
        host.state = host.tick()
        host.hold_gravity(20)
        _, status = _push_then_silence(host, 80)
        first_latched = next(i for i, s in enumerate(status) if s & HOLDING)
        assert 49 <= first_latched <= 52 and status[first_latched] & WATCHDOG and not status[first_latched] & STALE
        assert len(bridge.trips) == 1 and not status[-1] & ENABLED
        q_stale = bridge.hold_q.copy()
        host.hold_gravity(5)  # commands again: ignored while latched, only a reset re-enables
        assert host.state[3] & HOLDING and np.allclose(bridge.hold_q, q_stale)
    finally:
        host.sock.close()
        bridge.link.close()


def test_the_bridge_stops_a_joint_beyond_its_limits_whatever_the_host_sends(hit):
    """Its own check, a margin wider than the host's safety layer: here nothing on the host checks the push."""
    lim = hit.model.limits
    bridge = Bridge(MujocoPlant(hit), watchdog_s=1.0, limits=BridgeLimits(lim.lower, lim.upper, lim.velocity))
    host = Host(bridge)
    try:
        host.send(Q0, CMD_RESET)
        host.state = host.tick()
        host.hold_gravity(20)
        speeds = []
        for _ in range(500):  # gravity and a push on the wrist, a fresh command every tick
            q, qd, _, status = host.state
            host.send(bridge.plant.gravity(q) + PUSH)
            host.state = host.tick()
            speeds.append(host.state[1][5])
            if host.state[3] & HOLDING:
                break
        assert host.state[3] & LIMIT and not host.state[3] & ENABLED
        assert bridge.trips[0][1].startswith("joint 5 too fast")
        assert 1.25 * lim.velocity[5] < abs(speeds[-2]) < 1.30 * lim.velocity[5]  # tripped at the first tick past
        for _ in range(300):  # held: the pushes are ignored, the wrist is brought to rest
            host.send(bridge.plant.gravity(host.state[0]) + PUSH)
            host.state = host.tick()
        assert abs(host.state[1][5]) < 0.05 and host.state[3] & HOLDING
    finally:
        host.sock.close()
        bridge.link.close()


def test_a_latched_bridge_is_reset_by_the_next_host_session(hit):
    """A new run is a new host process numbering its commands from 1: its reset opens a session (once dropped as
    out of order, so a bridge started by hand answered one run only: "does not answer")."""
    bridge = Bridge(MujocoPlant(hit), watchdog_s=0.050, stale_s=0.010)
    first = Host(bridge)
    try:
        first.send(Q0, CMD_RESET)
        first.state = first.tick()
        first.hold_gravity(30)
        for _ in range(60):  # the run ended: no more commands, the watchdog latches a hold
            first.state = first.tick()
        assert first.state[3] & HOLDING and first.seq > 30
        second = Host(bridge)
        second.now = first.now
        try:
            second.send(Q0, CMD_RESET)  # seq 1 again
            second.state = second.tick()
            assert second.state[3] & ENABLED and not second.state[3] & HOLDING
            q, *_ = second.hold_gravity(40)
            assert np.abs(q - Q0).max() < np.radians(1) and bridge.rx.dropped["out-of-order"] == 0
        finally:
            second.sock.close()
    finally:
        first.sock.close()
        bridge.link.close()


def test_a_bridge_started_by_hand_has_the_hosts_watchdog_defaults():
    from rehabkit.cli.main import parser
    from rehabkit.hardware.config import HardwareConfig

    args = parser().parse_args(["bridge", "hit"])
    assert args.watchdog_ms is None and args.stale_ms is None  # resolved to the host's when the bridge starts
    assert HardwareConfig().bridge_watchdog_ms == 50.0 and HardwareConfig().bridge_stale_ms == 10.0


def test_a_reset_sent_again_keeps_the_ramp_in_after_a_clear(hit, tmp_path):
    """The first session after an e-stop was cleared ramps in; a host whose reset's answer came late sends the reset
    again — the second reset must not lose the ramp the first one took from the latch (it did: a loaded machine's
    session after a clear started at full stiffness)."""
    from rehabkit.core.safety.estop import EStopLatch
    from rehabkit.hardware.link.protocol import RAMP_IN

    latch = EStopLatch(tmp_path / "hit-1.json", "hit-1")
    latch.press("test", "host")
    latch.clear("J. Doe")
    host = Host(Bridge(MujocoPlant(hit), watchdog_s=1.0, latch=latch))
    host.send(Q0, CMD_RESET)
    first = host.tick()[3]
    host.send(Q0, CMD_RESET)  # (sent again)
    again = host.tick()[3]
    assert first & RAMP_IN and again & RAMP_IN and not latch.take_ramp_in()  # (taken once)
    host.state = host.tick()
    host.hold_gravity(5)
    host.send(Q0, CMD_RESET)  # a new session after commands: no ramp-in any more
    assert not host.tick()[3] & RAMP_IN


def test_a_light_joint_is_held_still_by_gains_its_tick_can_apply():
    """urdf_arm4's wrist weighs 1.05 g·m² at the joint: the bridge's hold damping of 6 N·m·s/rad applied once a 1 ms
    tick is 5.7 times what it can take (it swung wider each tick: a new user's 0.8 g·m² wrist reached 634 °/s 3 ms
    into a real-time session, before the host's first command). The hold's gains are made stable for each joint's
    inertia, as the safety layer's own hold: held after a reset without a command, the arm stays where it was put."""
    import yaml

    from rehabkit.core.kinds.context import Context
    from rehabkit.core.plugins.registry import default_registry
    from tests.conftest import ROOT

    folder = ROOT / "examples" / "robots"
    section = yaml.safe_load((folder / "urdf_arm4.yaml").read_text())["robot"]
    info = default_registry().get("robot", section["type"])
    robot = info.factory(info.config.model_validate(section), Context(folder, np.random.default_rng(0), 0.001))
    plant = MujocoPlant(robot)
    bridge = Bridge(plant, watchdog_s=1.0)
    host = Host(bridge)
    q0 = np.radians([-50.0, 20.0, 60.0, 20.0])
    host.send(q0, CMD_RESET)
    speeds, moved = [], []
    for _ in range(300):  # 0.3 s held at the start posture, no command from the host
        q, qd, _, status = host.tick()
        speeds.append(np.abs(qd).max())
        moved.append(np.abs(q - q0).max())
    assert status & ENABLED and not status & (HOLDING | LIMIT)
    assert max(speeds) < np.radians(5.0) and max(moved) < np.radians(0.5)
    kp, kd = bridge._hold_gains()
    assert kd[3] * plant.timestep / plant.joint_inertia()[3] <= 0.5 + 1e-9 and kd[0] == 6.0 and kp[0] == 60.0
