"""The hardware backend's settings (the ``backend:`` section of a scenario run over the link) and its faults."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from rehabkit.core.kinds.errors import SettingError, with_fix
from rehabkit.core.kinds.interfaces import BackendFaultError, StrictModel
from rehabkit.hardware.security.keys import KeyFileError, LinkKey, check_robot, load_key
from rehabkit.models.strict import FilePath


class LinkLostError(BackendFaultError):
    """No valid state from the robot for longer than allowed. ``cause_code``: ``state-timeout`` (the host's state
    watchdog ran out), ``tick-unanswered`` (a lock-step tick went unanswered), or None where neither is why."""

    def __init__(self, message: str, cause_code: str | None = None):
        super().__init__(message)
        self.cause_code = cause_code  # (why as a code: the message says it in words)


class SessionTakenOverError(LinkLostError):
    """The bridge ended this host's session: another host's took it over (the bridge's BYE, sealed in this session).
    ``bridge`` (its address), ``allowed``: how — "keypad" (the person at the robot allowed it on the bridge's keypad,
    ``a``, while this run was live) or "silent" (after this host's session fell silent)."""

    def __init__(self, bridge: str, allowed: str):
        self.bridge, self.allowed = bridge, allowed
        how = ("the person at the robot allowed it on the bridge's keypad (a)" if allowed == "keypad" else
               "this host's session had fallen silent")
        super().__init__(f"the session with the bridge at {bridge} was taken over by another host ({how}): the robot "
                         "is that host's now, and this run stops")


class LinkBusyError(BackendFaultError):
    """The bridge refuses this host's session for another host's live one (the keys match): ``bridge`` (its address),
    ``problem`` (what it said, and how a new host gets in)."""

    def __init__(self, bridge: str, problem: str):
        self.bridge, self.problem = bridge, problem
        super().__init__(f"the bridge at {bridge} refuses this host's session: {problem}")


class LinkKeyError(BackendFaultError):
    """The bridge and this host do not share the robot's key: ``bridge`` (its address), ``key_file`` (this host's,
    or None), ``problem`` (which side lacks what, naming key ids), ``fix`` (what gives both ends the same key);
    ``reason``: the bridge's refusal as its code (``no-key``, ``other-key``, ``key-needed``; ``forged``: it could not
    prove the key), where known; ``key_id``: this host's key's id (None without a key)."""

    def __init__(self, bridge: str, key_file: str | None, problem: str, reason: str | None = None,
                 key_id: str | None = None):
        self.bridge, self.key_file, self.problem = bridge, key_file, problem
        self.reason, self.key_id = reason, key_id
        self.fix = (f"give both ends the same key file (the bridge's --key, this scenario's backend.key_file: "
                    f"{key_file})" if key_file else
                    "set backend.key_file to the robot's key file (the one the bridge was given)")
        self.said = f"the bridge at {bridge} refuses this host's session: {problem}"
        super().__init__(with_fix(self.said, self.fix))


class BridgeHoldError(BackendFaultError):
    """The bridge stopped the robot on its own (its command watchdog, an e-stop at the robot, its own limit check:
    then ``breach``, the limit it saw broken); it still reports the robot's state. ``status``: the status bits the
    bridge held with (its ``WATCHDOG``, ``ESTOPPED`` or ``LIMIT`` bit says why; 0 where not given), ``at_s``: when,
    in seconds from the run's start (None where not given)."""

    observable = True
    cause_code = "bridge-hold"

    def __init__(self, message: str, breach=None, status: int = 0, at_s: float | None = None):
        super().__init__(message)
        self.breach = breach
        self.status, self.at_s = status, at_s  # (why and when as fields: the message says them in words)


class HardwareConfig(StrictModel):
    """Where the bridge is, the loop rate and the host watchdog."""

    host: str = "127.0.0.1"
    port: int = Field(0, ge=0, le=65535, description="bridge UDP port (0 with spawn_bridge: any free one)")
    spawn_bridge: bool = Field(True, description="start 'rehabkit bridge' with the robot's MuJoCo model as plant")
    clock: Literal["realtime", "lockstep"] = Field(
        "realtime", description="realtime: both ends tick on the wall clock, as a robot's drives do; lockstep: "
        "the bridge ticks once per host tick, on the host's clock (a simulated plant only: deterministic and "
        "faster than real time, for tests and rehearsals; the bridge must be started with --lockstep)")
    robot_id: int = Field(1, ge=0)
    key_file: FilePath | None = Field(
        None, description="the robot's link key (`rehabkit keys new ROBOT-ID`; the same file at the bridge): the "
        "link then runs in authenticated sessions only. Needed for a bridge beyond this machine's loopback")
    rekey_s: float = Field(120.0, gt=0, description="with a key: the session is re-keyed (a new handshake, new "
                           "ephemeral keys, alongside the stream) after this long [s, the link's time]")
    timestep: float = Field(0.001, ge=0.0002, le=0.01, description="link period (the bridge's plant step too) [s]")
    # defaults for a host without a real-time kernel: this 2-core VM stalls a process by up to ~10-17 ms now
    # and then; with an RT kernel both can be far tighter (the watchdog tests run the bridge's at 5 ms)
    state_timeout_s: float = Field(0.1, gt=0, description="host watchdog: no valid state for this long stops")
    max_age_s: float = Field(0.005, gt=0, description="older states are stale and dropped")
    bridge_watchdog_ms: float = Field(50.0, gt=0, description="bridge holds the robot without commands this long")
    bridge_stale_ms: float = Field(10.0, gt=0, description="bridge holds the posture without a newer command this "
                                   "long, until the next one (no torque is applied open-loop for longer)")
    cut_commands_at_s: float | None = Field(None, gt=0, description="a fault injected for a safety-skill test: "
                                            "from this time on no command leaves the host (a cut link)")

    def under(self, safety) -> HardwareConfig:
        """These settings with the scenario's safety envelope's link timing (``safety.heartbeat``) over them."""
        beat = safety.heartbeat if safety is not None else None
        if beat is None:
            return self
        return self.model_copy(update={"bridge_watchdog_ms": beat.command_timeout_ms,
                                       "bridge_stale_ms": beat.hold_after,
                                       "state_timeout_s": beat.state_timeout_ms / 1e3})

    def key(self, context) -> LinkKey | None:
        """The robot's link key, if the scenario names one: refused at ``key_file`` if unusable or another robot's,
        and at ``host`` if there is none and the bridge is beyond this machine's loopback."""
        if self.key_file is None:
            if not loopback(self.host):  # (anyone on that network could pose as the bridge, or drive the robot)
                raise SettingError("host", f"{self.host} is beyond this machine's loopback, and the link has no key: "
                                   "give both ends the robot's key (backend.key_file here, the bridge's --key there; "
                                   f"`rehabkit keys new {context.robot.model.name}-{self.robot_id}` makes one)")
            return None
        try:
            key = load_key(context.resolve(self.key_file))
            check_robot(key, f"{context.robot.model.name}-{self.robot_id}")
        except KeyFileError as exc:
            raise SettingError("key_file", f"{exc.path}: {exc.problem}", fix=exc.fix) from None
        return key


def loopback(host: str) -> bool:
    """``host`` is this machine's loopback (an address in 127.0.0.0/8 or ::1, or ``localhost``)."""
    import ipaddress

    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return host == "localhost"
