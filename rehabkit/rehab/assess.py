"""Range-of-motion assessment, as clinical practice does it at the start of a session: two runs of the scenario's
robot, backend and person, then a new version of the person's profile.

1. **Active**: the robot transparent (gravity and friction compensated, no stiffness — the ``transparent``
   controller) while the person is cued to move one joint at a time as far as they can each way (joint-space
   goals at the robot's limits); each joint's active range is the span it reached while cued.
2. **Passive**: the person relaxed; a slow robot-driven stretch of each joint out to the end-feel and back
   (``passive-stretch``); each end where it stopped is the passive range.

Both runs leave the profile's ranges out of the limits (they are what is measured: the robot's own, the
envelope's and its checks stay in force); a simulated person keeps them as the truth it moves by. The measured
ranges go into ``DIR/<id>.v<N>.yaml`` — the profile with ``version`` N and ``assessed`` filled in — which
narrows the next session's limits (``--set patient=DIR/<id>.v<N>.yaml``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import date
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml

from rehabkit.core.io import atomic_write_json, atomic_write_text
from rehabkit.core.kinds.interfaces import InteractionForceSensor
from rehabkit.core.plugins.registry import default_registry
from rehabkit.core.scenario.loader import LoadedScenario, load_scenario
from rehabkit.core.scenario.source import parse_override
from rehabkit.core.setup.errors import SetupError

if TYPE_CHECKING:
    from rehabkit.models.robot_model import RobotModel
    from rehabkit.rehab.profile import PatientBase

CUE_S = 3.0  # each cue (a joint to one end, to the other, back) [s]
CUE_MARGINS = (0.08, 0.12, 0.16, 0.2, 0.25)  # cues this share of a joint's range inside the robot's limits, the
# first whose plan (a spline that swings past its via points) stays within them


@dataclass
class Assessment:
    """What an assessment measured [deg], per joint, and where it wrote it."""

    active: dict[str, tuple[float, float] | None]  # None: a safety stop ended the session before its cues did
    passive: dict[str, tuple[float | None, float | None]]
    stopped_by: dict[str, tuple[str | None, str | None]]  # each passive end: end-feel, torque cap, robot limit, or
    # a safety stop (the angle reached then: a bound on the range)
    profile_file: Path
    runs: dict[str, Any] = field(default_factory=dict)  # the two runs' results

    @property
    def complete(self) -> bool:
        """Every range measured (no session cut short by a safety stop, nor touching the scene)."""
        return all(a is not None for a in self.active.values()) and all(
            why in MEASURED for whys in self.stopped_by.values() for why in whys)


def _sessions_base(loaded: LoadedScenario) -> dict[str, Any]:
    """Overrides every session of the assessment shares: the profile's ranges out of the limits (the simulated
    person keeps them as its own), no task events, expectations, keep-in box (a task's workspace: the stretch goes
    to the joints' ends) or sensors but force sensors; every other limit of the envelope stays."""
    sc, registry, raw = loaded.model, default_registry(), loaded.source.data
    profile = sc.patient

    def drop(section: str, *keys: str) -> dict:  # (null removes a key that is there; one that is not, it would set)
        return {k: None for k in keys if k in (raw.get(section) or {})}

    over: dict[str, Any] = {"patient": drop("patient", "joints"), "expect": drop("expect", *sc.expect),
                            "task": drop("task", "events", "sequence", "start"),
                            "safety": {"ramp_out_s": 0.0, **drop("safety", "keep_in")}}
    model = getattr(profile, "model", None)
    if model is not None and "rom" in type(model).model_fields and model.rom is None and profile.joints:
        over["patient"]["model"] = {"rom": {j: r.model_dump(mode="json") for j, r in profile.joints.items()}}
    dropped = {name: None for name, cfg in sc.sensors.items()
               if not issubclass(registry.get("sensor", cfg.type).factory, InteractionForceSensor)}
    if dropped:
        over["sensors"] = dropped
    return over


def _merge(a: dict, b: dict) -> dict:
    """``b`` over ``a``, mappings merged; unlike the loader's ``deep_merge`` a null is kept, not applied: it is the
    loader's own merge of these overrides onto the scenario that removes what a null marks."""
    out = dict(a)
    for k, v in b.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def _assembled(path: Path, overrides: dict):
    """The run's setup up to its targets (robot built, limits narrowed): no plugin beyond the robot."""
    from rehabkit.core.plugins.lifecycle import default_extensions
    from rehabkit.core.setup.assembly import assemble

    return assemble(load_scenario(path, overrides), default_registry(), default_extensions(), upto="targets")


def assess(path: str | Path, out_dir: str | Path, overrides: Any = (), joints: list[str] | None = None,
           cue_s: float = CUE_S, damping: float = 0.0, stretch_settings: dict[str, Any] | None = None
           ) -> Assessment:
    """Assess the range of motion of the person in scenario ``path`` (see the module docstring); ``damping``: the
    viscous damping the transparent robot keeps [N·m·s/rad]; ``stretch_settings``: the passive stretch's."""
    stretcher = default_registry().get("controller", "passive-stretch")  # (a plugin: found by name, not imported)

    from rehabkit.core.setup.first_plan import start_posture

    path, out = Path(path), Path(out_dir)
    given = dict(overrides) if isinstance(overrides, Mapping) else {
        ".".join(key): value for key, value in map(parse_override, overrides)}
    setup = _assembled(path, given)  # the scenario as given: where it starts, within the profile's ranges
    loaded, profile, q0 = setup.loaded, setup.sc.patient, start_posture(setup)
    if profile is None:
        raise SetupError(f"{path}: an assessment needs a patient profile (patient: FILE)", setting="patient")
    if isinstance(given.get("patient"), str):  # a profile --set names: inlined, as the sessions change it
        given["patient"] = loaded.source.data["patient"]
    base = _merge(given, _sessions_base(loaded))
    sessions = _assembled(path, base)  # the profile's ranges out of the limits
    model = sessions.robot.model
    names = assessed_joints(model, profile, joints)
    idx = [model.joint_names.index(j) for j in names]
    lo, hi = model.limits.lower, model.limits.upper

    # 1. active: cued to each end of each joint in turn, the robot transparent
    start = posture_target("start", q0)
    cues = _cues(sessions, q0, idx, lo, hi, cue_s)
    active_over = _merge(base, {
        "planner": {"type": "multi-cubic", "segment_durations": [cue_s] * len(cues)},
        "controller": {"type": "transparent", "damping_nms_rad": damping},
        "task": {"targets": [start, *cues]}, "duration": cue_s * (len(cues) + 1)})
    active_run = run_scenario(path, active_over, out_dir=out / "active")
    t, q = active_run.trace.t, np.degrees(active_run.trace.q)
    end = _stopped_at(active_run)
    active: dict[str, tuple[float, float] | None] = {}
    for n, (name, j) in enumerate(zip(names, idx)):
        window = (t >= cue_s * 3 * n) & (t < cue_s * 3 * (n + 1))
        done = end is None or end >= cue_s * 3 * (n + 1)  # (a safety stop before its cues ended: not measured)
        active[name] = (float(q[window, j].min()), float(q[window, j].max())) if done and window.any() else None

    # 2. passive: relaxed, stretched to the end-feel
    stretch = stretcher.config.model_validate({**(stretch_settings or {}), "type": "passive-stretch", "joints": names})
    passive_over = _merge(base, {
        "patient": {"model": _relaxed(profile)},
        "planner": {"type": "multi-cubic", "segment_durations": [1.0]},
        "controller": stretch.model_dump(mode="json"),
        "task": {"targets": [start, {"name": "hold", "same_as": "start"}]},  # (its reference is its own)
        "duration": float(stretcher.factory.duration(q0, lo, hi, idx, stretch))})
    passive_run = run_scenario(path, passive_over, out_dir=out / "passive")
    passive, stopped = _passive_ends(passive_run, names, idx)
    # a robot touching the scene measures the scene, not the person: nothing of such a session is kept
    if active_run.summary["metrics"].get("contact_steps"):
        active = dict.fromkeys(active, None)
    if passive_run.summary["metrics"].get("contact_steps"):
        passive = {j: (None, None) for j in passive}
        stopped = {j: ("contact", "contact") for j in stopped}

    profile_file = write_profile(loaded, out, active, passive, stopped)
    result = Assessment(active, passive, stopped, profile_file, {"active": active_run, "passive": passive_run})
    atomic_write_json(out / "assessment.json", {
        "scenario": str(path), "patient": profile.id, "profile": str(profile_file),
        "active_deg": active, "passive_deg": passive, "passive_stopped_by": stopped,
        "sessions_stopped": {k: r.summary["safety"]["events"][0]["message"] for k, r in result.runs.items()
                             if r.summary["safety"]["events"]},
        "contact_steps": {k: r.summary["metrics"].get("contact_steps", 0) for k, r in result.runs.items()},
        "previous_deg": {j: {"active": list(r.active_deg) if r.active_deg else None, "passive": list(r.passive_deg)}
                         for j, r in profile.joints.items()}})
    return result


WHY = {0: "end-feel", 1: "torque cap", 2: "robot limit", 3: "force cap"}
MEASURED = set(WHY.values())  # (a safety stop's angle is a bound on the range, not its end)


def _stopped_at(run) -> float | None:
    events = run.summary["safety"]["events"]
    return events[0]["t"] if events else None


def _passive_ends(run, names: list[str], idx: list[int]) -> tuple[dict, dict]:
    """Each joint's (lower, upper) passive end and what ended it; a stretch under way when a safety stop ended the
    session gets the angle it reached ("safety stop: <rule>"), the ones not begun by then none."""
    m, trip = run.summary["metrics"], _stopped_at(run)
    passive: dict[str, list] = {}
    stopped: dict[str, list] = {}
    pending = True  # the first end missing is the stretch the safety stop cut short
    for name, j in zip(names, idx):
        ends, whys = [None, None], [None, None]
        for k, side in ((1, "upper"), (0, "lower")):  # (the order of the stretches)
            key = f"passive_rom_deg_{side}_{name}"
            if key in m and (trip is None or m[f"passive_stop_t_{side}_{name}"] < trip):  # (not after the stop)
                ends[k], whys[k] = m[key], WHY[int(m[f"passive_stop_{side}_{name}"])]
            elif trip is not None and pending and m.get(f"passive_start_t_{side}_{name}", np.inf) < trip:
                row = int(np.searchsorted(run.trace.t, trip))
                ends[k] = float(np.degrees(run.trace.q[min(row, len(run.trace.t) - 1), j]))
                whys[k] = f"safety stop: {run.summary['safety']['events'][0]['rule']}"
                pending = False
        passive[name], stopped[name] = tuple(ends), tuple(whys)
    return passive, stopped


def posture_target(name: str, q: np.ndarray) -> dict[str, Any]:
    """A session's target at posture ``q`` in SI values (``joints_rad``: radians, metres for a prismatic joint), so
    that a robot with a slide is cued as one without."""
    return {"name": name, "joints_rad": np.asarray(q, float).round(9).tolist()}


def assessed_joints(model: RobotModel, profile: PatientBase, joints: list[str] | None = None) -> list[str]:
    """The joints an assessment measures: ``joints`` as named, else the profile's, else every revolute joint of
    ``model`` (a person's range of motion is an angle: a prismatic joint is not assessed).

    Raises:
        ValueError: a named joint the robot lacks, or a prismatic one (said as ``--joints: ...``).
    """
    turning = [n for n, turns in zip(model.joint_names, model.revolute, strict=True) if turns]
    if not joints:
        return [j for j in turning if j in profile.joints] or turning
    from rehabkit.core.kinds.errors import with_fix
    from rehabkit.core.setup.limits import unknown_joint

    for name in joints:
        if (said := unknown_joint(name, model)) is not None:
            raise ValueError(f"--joints: {with_fix(*said)}")
        if name not in turning:
            raise ValueError(f"--joints: {name} is a prismatic joint: an assessment measures a person's range of "
                             f"motion on revolute joints (in degrees); leave it out (its revolute joints: "
                             f"{','.join(turning)})")
    return list(joints)


def run_scenario(path: Path, overrides: dict, out_dir: Path):
    """One session of the assessment."""
    from rehabkit.core.run.runner import Runner

    return Runner(load_scenario(path, overrides), out_dir=out_dir).run()


def _cues(a, q0: np.ndarray, idx: list[int], lo: np.ndarray, hi: np.ndarray, cue_s: float) -> list[dict]:
    """Joint-space cues to each end of each joint and back, as far out as the cue plan (a C2 spline through them,
    which swings past its via points) stays within the robot's limits."""
    from rehabkit.core.kinds.interfaces import PlanRequest, Target
    from rehabkit.core.safety.limit_breach import plan_breach

    info = default_registry().get("planner", "multi-cubic")
    for share in CUE_MARGINS:
        margin = share * (hi - lo)
        points = []
        for j in idx:
            for end in (hi[j] - margin[j], lo[j] + margin[j], q0[j]):
                q = q0.copy()
                q[j] = end
                points.append(q)
        planner = info.factory(info.config.model_validate({"type": "multi-cubic",
                                                           "segment_durations": [cue_s] * len(points)}), a.context)
        targets = [Target("start", q=q0), *(Target(f"cue{i}", q=p) for i, p in enumerate(points))]
        plan = planner.plan(PlanRequest(0.0, q0, np.zeros_like(q0), targets, a.robot))
        if plan_breach(plan, a.robot.model) is None:
            return [posture_target(f"cue{i}", p) for i, p in enumerate(points)]
    raise SetupError("no cue plan within the robot's limits (its joints' ranges are too narrow to cue)")


def _relaxed(profile) -> dict:
    """The settings leaving the simulated person (if any) relaxed: the patient plugin says which."""
    model = getattr(profile, "model", None)
    return dict(default_registry().get("patient", model.type).factory.relaxed) if model is not None else {}


def write_profile(loaded: LoadedScenario, out: Path, active: dict, passive: dict, stopped: dict) -> Path:
    """The profile with the measured ranges (those measured: a range cut short by a safety stop keeps its previous
    value), as its next version, written whole into ``out``."""
    profile = loaded.model.patient
    data = profile.model_dump(mode="json", exclude_unset=True)
    version = int(data.get("version", 1)) + 1
    joints = data.setdefault("joints", {})
    for name, ends in passive.items():
        entry = joints.setdefault(name, {})
        old = entry.get("passive_deg", [None, None])
        p = [round(e, 1) if e is not None and why in MEASURED else o for e, why, o in zip(ends, stopped[name], old)]
        if None not in p:
            entry["passive_deg"] = p
        if active.get(name) is not None and "passive_deg" in entry:
            a_lo, a_hi = active[name]  # (inside the passive range: an active reach past it is the stretch's bound)
            lo_p, hi_p = entry["passive_deg"]
            entry["active_deg"] = [round(max(a_lo, lo_p), 1), round(min(a_hi, hi_p), 1)]
        if not entry:
            del joints[name]
    data["version"] = version
    data["assessed"] = {"date": date.today().isoformat(), "method": "rehabkit assess: active (transparent robot, "
                        "cued), passive (stretch to the end-feel)", "scenario": str(loaded.path)}
    path = out / f"{profile.id}.v{version}.yaml"
    text = (f"# {profile.id}, version {version}: ranges measured by `rehabkit assess` on {date.today()}\n"
            + yaml.safe_dump(data, sort_keys=False, allow_unicode=True))
    atomic_write_text(path, text)
    return path
