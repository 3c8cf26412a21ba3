"""``rehabkit safety-report``: run safety-skill scenarios in simulation, over the robot link and on CANopen drives
and tabulate, skill by skill, what triggered each stop, how fast it reacted, how far and how long the robot went on,
and the peak force — Markdown and HTML (with plots) side by side, for an ethics board or a risk file.

Each scenario runs as written (simulation), with ``backend.type: hardware`` on a lock-step link to a bridge
driving the robot's MuJoCo model (a scenario already on the hardware backend runs over the link only), and with
``backend.type: canopen`` on simulated CiA 402 drives on a lock-step bus, at the highest of 1000, 500, 250 Hz the bus
arithmetic allows (a cut link there is the host's heartbeat no longer reaching the drives). Every run
keeps its e-stop latches to itself; a scenario that presses the e-stop also shows the latch: the next session is
refused until cleared, and the one after the clear ramps in. The reaction time is from the moment the limit was
first crossed in truth (the rig's push reaching the force limit — a spring rig's from where its mount went — a
joint leaving its range or going too fast, the e-stop pressed, the link cut) to the safety layer's trip (or the
bridge's hold). ``--reactions`` runs each force skill once per force-limiting reaction (stop, yield, retreat).
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

LINK = {"backend": {"type": "hardware", "clock": "lockstep"}}
CANOPEN = {"type": "canopen", "clock": "lockstep"}
BACKENDS = ("simulation", "link", "canopen")
MARGIN_DEG = 0.5  # the envelope's default tolerance past a range: the truth crossed the range itself


@dataclass
class SkillRun:
    """One scenario on one backend, as the report tells it."""

    scenario: str
    backend: str
    passed: bool
    trigger: str
    onset_s: float | None
    trip_s: float | None
    category: int | None
    figures: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    trace: Any = None
    failed: tuple[str, ...] = ()  # the expectations it did not meet (their metrics), or why else it did not pass

    @property
    def reaction_ms(self) -> float | None:
        if self.onset_s is None or self.trip_s is None:
            return None
        return 1e3 * (self.trip_s - self.onset_s)


def _spring_push(setup, load, trace) -> np.ndarray | None:
    """The force a spring load (``stiffness_n_m``) put on a force-torque sensor's mount at each step of the trace
    [N], from where the mount was (the robot's kinematics at the traced postures); None where that can't be told
    (then the limit's crossing is the measured force's, the filter's lag not counted)."""
    import pinocchio as pin

    sensor = next((s for s in setup.sensors.values() if getattr(s, "name", None) == load.body), None)
    model = setup.robot.model
    try:
        pm = model.pin_model
    except Exception:  # noqa: BLE001 (no Pinocchio model: a closed chain)
        return None
    if sensor is None or not pm.existFrame(sensor.body) or model.passive_joints:
        return None  # (a passive joint's angle is not traced: where the mount went can't be told)
    data, frame = pm.createData(), pm.getFrameId(sensor.body)
    at = np.empty((len(trace.t), 3))
    for k, q in enumerate(trace.q):
        pin.framesForwardKinematics(pm, data, q)
        at[k] = data.oMf[frame].act(np.asarray(sensor.position, float))
    at = model.to_world(at)
    full = float(np.linalg.norm(load.force_n))
    along = np.asarray(load.force_n, float) / full
    share = np.array([load.at(s) for s in trace.t])
    k0 = int(np.searchsorted(trace.t, load.start_s - 1e-12))
    if k0 >= len(trace.t):
        return np.zeros(len(trace.t))
    squeeze = share * full / load.stiffness_n_m - (at - at[k0]) @ along
    return np.where(share > 0, load.stiffness_n_m * np.maximum(squeeze, 0.0), 0.0)


def _onset(sc, event: dict, trace, setup=None) -> float | None:
    """When the limit the trip enforces was first crossed in truth."""
    rule, t = event["rule"], trace.t
    springs = [x for x in sc.world.loads if x.stiffness_n_m is not None] if sc.world else []
    if rule == "interaction-force" and springs and setup is not None and len(springs) == len(sc.world.loads) == 1:
        push = _spring_push(setup, springs[0], trace)
        if push is not None:
            over = np.flatnonzero(push >= event["limit"])
            return float(t[over[0]]) if len(over) else None
    if rule == "interaction-force" and sc.world.loads and not springs:
        grid = np.arange(0.0, sc.duration, 1e-4)
        push = np.linalg.norm(sum(np.outer([x.at(s) for s in grid], x.force_n) for x in sc.world.loads), axis=1)
        over = np.flatnonzero(push >= event["limit"])
        return float(grid[over[0]]) if len(over) else None
    if rule == "interaction-force" and trace.f_h is not None:
        over = np.flatnonzero(trace.f_h > event["limit"])
        return float(t[over[0]]) if len(over) else None
    if rule in ("position", "velocity") and "_joint_index" in event:
        j, limit = event["_joint_index"], event["limit"]
        if rule == "velocity":
            beyond = np.abs(trace.qd[:, j]) > abs(limit)
        elif event["value"] > limit:  # past the upper end: the range ends a margin inside the trip's limit
            beyond = trace.q[:, j] > limit - math.radians(MARGIN_DEG)
        else:
            beyond = trace.q[:, j] < limit + math.radians(MARGIN_DEG)
        hits = np.flatnonzero(beyond)
        return float(t[hits[0]]) if len(hits) else None
    if rule == "e-stop":
        return event["t"]
    if rule == "backend":
        cut = getattr(sc.backend, "cut_commands_at_s", None)
        injected = getattr(sc.backend, "inject", None)
        return injected[0].at_s if injected else cut
    return None


def run_skill(path: Path, backend: str, reaction: str | None = None) -> SkillRun:
    """Run one skill scenario on ``backend`` (``simulation`` or ``link``), its latches its own; ``reaction``: the
    interaction-force limit's reaction in place of the scenario's (stop, yield, retreat)."""
    from rehabkit.api import run_scenario
    from rehabkit.core.kinds.backend import EStopLatchedError
    from rehabkit.core.run.runner import Runner
    from rehabkit.core.safety.estop import own_state
    from rehabkit.core.scenario.loader import load_scenario
    from rehabkit.core.setup.errors import SetupError

    overrides = dict(LINK) if backend == "link" else {}
    if reaction is not None:
        overrides["safety.reactions"] = {"interaction-force": {"type": reaction}}
    if backend == "canopen":
        overrides = _on_canopen(path, overrides)
    loaded = load_scenario(path, overrides)
    sc = loaded.model
    with tempfile.TemporaryDirectory() as state, own_state(Path(state)):
        runner = Runner(loaded)
        result = runner.run()  # (loaded once: the scenario is read for the onsets too)
        notes = [f"at {sc.rates.control_hz:g} Hz, the highest of 1000, 500, 250 Hz the bus carries"] \
            if backend == "canopen" else []
        events = result.summary["safety"]["events"]
        if events and events[0]["rule"] == "e-stop":  # the latch: refused, cleared, ramped in
            try:
                run_scenario(path, overrides, out_dir=None)
                notes.append("e-stop NOT latched: the next session ran")
            except SetupError as exc:
                latched = isinstance(exc.__cause__, EStopLatchedError)
                notes.append("the next session was refused: e-stop latched" if latched else str(exc))
            from rehabkit.core.safety.estop import RAMP_IN_AFTER_CLEAR_S, all_latches

            for latch in all_latches():
                latch.clear("safety-report (validation protocol)")
            # the session after the clear runs through its ramp-in (at least RAMP_IN_AFTER_CLEAR_S), not the whole
            # scenario again: what it is run for is that ramp, and going on would press the e-stop again, latching
            # the robot the protocol has just cleared (and, over the link, a second of lock-step ticks for nothing)
            ramp_s = max(RAMP_IN_AFTER_CLEAR_S, sc.safety.ramp_in_s)
            after = {**overrides, "duration": min(sc.duration, ramp_s)}
            ramp = [e["data"].get("duration_s") for e in run_scenario(path, after, out_dir=None)
                    .summary["safety"]["interventions"] if e["rule"] == "ramp-in"]
            notes.append(f"cleared, then ramped in over {ramp[0]:g} s" if ramp else "cleared, no ramp-in")
    m = result.summary["metrics"]
    figures = {k: m[k] for k in ("stop_time_s", "stop_distance_deg", "stop_distance_m", "stop_peak_speed_deg_s",
                                 "stop_joint_travel_m", "stop_joint_peak_speed_m_s",
                                 "ft_peak_force_n", "peak_interaction_force_n", "ft_bias_n", "ft_noise_n",
                                 "ft_noise_filtered_n", "force_after_trip_peak_n", "force_above_limit_s",
                                 "joints_in_range") if m.get(k) is not None}
    if not events:
        ramp = next((e for e in result.summary["safety"]["interventions"] if e["rule"] == "ramp-in"), None)
        tau = result.trace.tau
        rate = float(np.abs(np.diff(tau, axis=0)).max() / (result.trace.t[1] - result.trace.t[0])) if len(tau) > 1 \
            else math.nan
        figures["torque_rate_max_nm_s"] = rate
        figures["ramp_in_s"] = ramp["data"]["duration_s"] if ramp else 0.0
        return SkillRun(sc.name or path.stem, backend, result.passed, "ramp-in" if ramp else "none", None, None,
                        None, figures, notes, result.trace, _failed(result))
    ev = dict(events[0])
    names = result.summary["per_joint"]
    if ev.get("joint") in names:
        ev["_joint_index"] = list(names).index(ev["joint"])
    onset, trip = _onset(sc, ev, result.trace, runner.setup), ev["t"]
    for later in result.summary["safety"]["interventions"]:  # what else acted while it stopped (a bridge's backstop)
        if later["t"] > ev["t"] and later["rule"] == "backend":
            notes.append(f"then at {later['t']:.3f} s: {later['cause']}")
    for brake in (e for e in result.summary["safety"]["interventions"] if e["rule"] == "brakes"):
        notes.append(brake["cause"])
    held = [e["t"] for e in result.summary["safety"]["interventions"] if e["rule"] == "stale-command"]
    if ev["rule"] == "backend" and held:  # the robot side held it first (its hold through a gap in the commands)
        trip = min(trip, held[0])
        notes.append(f"the bridge held the robot at {held[0]:.3f} s; the host learnt of it at {ev['t']:.3f} s")
    # the event's own words: "measured: elbow_2 beyond its position limit (45.6°, limit 45.5°)", "interaction force
    # above its limit: 30.03 (limit 30)"
    trigger = f"{ev['rule']}: {ev['cause']}"
    for later in result.summary["safety"]["events"][1:]:  # a reaction that ended in a stop
        if later["data"].get("during"):
            notes.append(f"then at {later['t']:.3f} s: {later['cause']}")
    name = (sc.name or path.stem) + (f"-{reaction}" if reaction is not None else "")
    return SkillRun(name, backend, result.passed, trigger, onset, trip,
                    ev["data"].get("category", ev["data"].get("reaction")), figures, notes, result.trace,
                    _failed(result))


def _failed(result) -> tuple[str, ...]:
    """What kept a run from passing: each expectation it missed (metric and bound), or a stop none expected."""
    missed = tuple(f"{e['metric']} {e['bound']}" for e in result.summary["expectations"] if not e["passed"])
    return missed or (() if result.passed else ("a safety stop the scenario does not expect",))


def _on_canopen(path: Path, overrides: dict) -> dict:
    """The overrides that take a skill scenario to simulated CANopen drives: the highest control rate of 1000, 500,
    250 Hz the bus carries (as ``validate`` decides it), and a cut link as the host's heartbeat no longer reaching
    the drives."""
    from rehabkit.core.plugins.lifecycle import default_extensions
    from rehabkit.core.plugins.registry import default_registry
    from rehabkit.core.scenario.loader import load_scenario
    from rehabkit.core.setup.assembly import assemble
    from rehabkit.core.setup.errors import PluginSetupError

    sc = load_scenario(path).model
    backend = dict(CANOPEN)
    cut = getattr(sc.backend, "cut_commands_at_s", None)
    if cut is not None:
        backend["inject"] = [{"at_s": cut, "fault": "host-heartbeat"}]
    for hz in (1000, 500, 250):
        out = {**overrides, "backend": backend, "rates.control_hz": min(hz, sc.rates.control_hz)}
        try:
            assemble(load_scenario(path, out), default_registry(), default_extensions(), upto="plugins")
            return out
        except PluginSetupError as exc:
            if exc.diagnostics[0].path != "rates.control_hz":
                raise
    return out


def skill_runs(paths: list[Path], reactions: list[str] | None = None,
               backends: tuple[str, ...] = BACKENDS) -> list[tuple[SkillRun | None, ...]]:
    """One run per backend of ``backends`` (simulation, link, canopen) per scenario, None where it does not apply
    (simulation for a scenario on the hardware backend; the robot's backends for a person simulated in the scene).
    With ``reactions`` a scenario with an interaction-force limit runs once per reaction (``stop``, ``yield``,
    ``retreat``)."""
    from rehabkit.core.scenario.loader import load_scenario

    out = []
    for path in paths:
        loaded = load_scenario(path)
        sc = loaded.model
        on_link, person = sc.backend.type == "hardware", _embodied(loaded)
        for reaction in (reactions or [None]) if sc.safety.interaction_force_n is not None else [None]:
            row = []
            for backend in backends:
                if (backend == "simulation" and on_link) or (backend != "simulation" and person):
                    row.append(None)  # (the person lives in the simulated scene: a robot drives a real one)
                    continue
                row.append(run_skill(path, backend, reaction))
            if person and row[0] is not None:
                row[0].notes.append("simulation only: the person is simulated in the scene")
            out.append(tuple(row))
    return out


def _embodied(loaded) -> bool:
    """The scenario's patient is a body in the simulated scene (a musculoskeletal arm)."""
    from rehabkit.core.kinds.patient import EmbodiedPatient
    from rehabkit.core.plugins.registry import default_registry

    person = loaded.model.patient  # (the rehab layer's section: a profile whose model is a patient plugin's)
    if person is None or person.model is None:
        return False
    factory = default_registry().get("patient", person.model.type).factory
    return isinstance(factory, type) and issubclass(factory, EmbodiedPatient)
