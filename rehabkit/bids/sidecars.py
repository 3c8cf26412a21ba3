"""What the dataset says about itself and each file (JSON sidecars, the README), from the runs and the study's
description (``--study FILE``: its name, authors, licence, institution, the robots' makers; placeholders without one).
"""

from __future__ import annotations

from typing import Any

import yaml

from rehabkit.bids.channels import Tracksys
from rehabkit.bids.events import HED_VERSION
from rehabkit.bids.run_folder import ExportError, RunFolder
from rehabkit.core.version import __version__

BIDS_VERSION = "1.11.1"
TYPES = ("ACCEL", "ANGACCEL", "GYRO", "JNTANG", "LATENCY", "MAGN", "MISC", "ORNT", "POS", "VEL")
STUDY_KEYS = {"name": str, "authors": list, "license": str, "acknowledgements": str, "how_to_acknowledge": str,
              "funding": list, "references": list, "instructions": str, "institution": dict, "robots": dict,
              "source": list}


def read_study(path) -> dict[str, Any]:
    """A study's description (YAML), its keys checked."""
    from pathlib import Path

    path = Path(path)
    if not path.exists():
        raise ExportError(path, "no such file", "give a YAML file with the study's name, authors, license, "
                          "institution (examples/study.yaml is one)")
    try:
        study = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as exc:
        raise ExportError(path, f"not YAML ({exc})", "fix the file (examples/study.yaml is one)") from exc
    if not isinstance(study, dict):
        raise ExportError(path, "not a mapping", "give keys such as name:, authors:, license:, institution:")
    for key, value in study.items():
        if key not in STUDY_KEYS:
            raise ExportError(f"{path}: {key}", "unknown key", f"the keys are {', '.join(STUDY_KEYS)}")
        if not isinstance(value, STUDY_KEYS[key]):
            raise ExportError(f"{path}: {key}", f"should be a {STUDY_KEYS[key].__name__}",
                              "see examples/study.yaml")
    return study


def dataset_description(study: dict, simulated: bool, tasks: list[str]) -> dict[str, Any]:
    name = study.get("name") or f"rehabkit sessions: {', '.join(tasks)}"
    desc = {"Name": name + (" (simulated)" if simulated and "simulat" not in name.lower() else ""),
            "BIDSVersion": BIDS_VERSION, "DatasetType": "raw", "License": study.get("license", "n/a"),
            "Authors": study.get("authors", ["n/a"]), "HEDVersion": HED_VERSION,
            "GeneratedBy": [{"Name": "rehabkit", "Version": __version__,
                             "Description": "rehabkit export bids: runs (summary.json, scenario.yaml and the ROS 2 bag "
                                            "run.mcap) as Motion-BIDS" + ("; every session simulated (MuJoCo): the "
                                                                          "robots and the people are models"
                                                                          if simulated else "")}],
            "SourceDatasets": study.get("source", [{"Version": f"rehabkit {__version__} run folders"}])}
    for key, field in (("acknowledgements", "Acknowledgements"), ("how_to_acknowledge", "HowToAcknowledge"),
                       ("funding", "Funding"), ("references", "ReferencesAndLinks")):
        if key in study:
            desc[field] = study[key]
    return desc


def _task_description(run: RunFolder) -> str:
    sc, plugins = run.scenario, run.summary.get("plugins", {})
    said = sc.get("description") or ""
    task = sc.get("task") or {}
    targets = [t.get("name") for t in task.get("targets", []) if isinstance(t, dict)]
    order = task.get("sequence") or targets
    how = (f"the {plugins.get('robot', {}).get('type')} robot moves the hand through the targets "
           f"{' → '.join(map(str, order))} ({plugins.get('planner', {}).get('type')} planner, "
           f"{plugins.get('controller', {}).get('type')} controller), {sc.get('duration')} s; "
           + ("simulated on MuJoCo" if run.simulated else f"on the robot ({run.backend} backend)"))
    person = run.profile.get("model", {}).get("type") if run.profile and run.simulated else None
    if person:
        how += f", the person a '{person}' model of profile {run.profile.get('id')}"
    return f"{said.strip()} ({how})" if said else how[0].upper() + how[1:]


def software(run: RunFolder) -> str:
    parts = [f"rehabkit {run.summary.get('rehabkit_version', __version__)}"]
    for kind, p in run.summary.get("plugins", {}).items():
        for name, q in (p.items() if kind == "sensors" else [(None, p)]):
            if isinstance(q, dict) and "type" in q:
                parts.append(f"{kind}{'/' + name if name else ''} {q['type']} ({q.get('package')} "
                             f"{q.get('version')})")
    return "; ".join(parts)


def motion_json(run: RunFolder, ts: Tracksys, study: dict, robot: bool) -> dict[str, Any]:
    """The motion file's sidecar: the task, the hardware and software, the rate, the channel counts."""
    kind = run.summary.get("plugins", {}).get("robot", {})
    maker = (study.get("robots") or {}).get(kind.get("type"), {})
    inst = study.get("institution") or {}
    n = len(ts.stamps)
    span = (ts.stamps[-1] - ts.stamps[0]) / 1e9 if n > 1 else 0.0
    counts = ts.counts()
    sim = " (simulated)" if run.simulated else ""
    out = {"TaskName": run.name, "TaskDescription": _task_description(run),
           "Instructions": study.get("instructions", "n/a"),
           "SamplingFrequency": ts.rate_hz,
           "SamplingFrequencyEffective": round((n - 1) / span, 6) if span > 0 else "n/a",
           "RecordingDuration": round(float(n / ts.rate_hz) if ts.rate_hz else span, 6),
           "TrackingSystemName": ts.name + sim,
           "Manufacturer": maker.get("manufacturer") or (f"{kind.get('package', 'rehabkit')} robot model, simulated "
                                                         "in MuJoCo" if run.simulated else "n/a"),
           "ManufacturersModelName": maker.get("model") or str(kind.get("type", "n/a")),
           "DeviceSerialNumber": maker.get("serial") or ("n/a (simulated)" if run.simulated else "n/a"),
           "SoftwareVersions": software(run),
           "InstitutionName": inst.get("name", "n/a"), "InstitutionAddress": inst.get("address", "n/a"),
           "InstitutionalDepartmentName": inst.get("department", "n/a"),
           "MotionChannelCount": len(ts.channels),
           **{f"{t}ChannelCount": counts.get(t, 0) for t in TYPES},
           "TrackedPointsCount": len({c.tracked_point for c in ts.channels}),
           "MissingValues": "n/a",
           "SubjectArtefactDescription": "n/a"}
    if robot:
        out["ControlRate"] = ts.rate_hz
        out["Backend"] = run.backend
    return out


def channels_json(ts: Tracksys) -> dict[str, Any]:
    used = {c.reference_frame for c in ts.channels}
    return {"reference_frame": {"LongName": "reference frame",
                                "Description": "the frame a channel's value is given in",
                                "Levels": {k: {"Description": v} for k, v in ts.frames.items() if k in used}},
            "description": {"Description": "what the channel is"}}


def readme(description: dict, participants: int, sessions: int, runs: int, simulated: bool) -> str:
    return f"""# {description['Name']}

Sessions of rehabilitation robotics recorded by rehabkit ({description['GeneratedBy'][0]['Version']}) and written as
Motion-BIDS by `rehabkit export bids`: {participants} participant(s), {sessions} session(s), {runs} run(s).
{"Every session was simulated (MuJoCo): the robots and the people are models, not recordings of anyone."
 if simulated else "Sessions on a robot are marked by their backend in each session's scans.tsv."}

- `participants.tsv`: each participant's pseudonymous profile id, treated side, impairment and its scale, segment
  lengths, and the model that stood in for them in a simulated session. Nothing else about a person is kept.
- `sub-*/ses-*/motion/*_tracksys-<robot>_*_motion.tsv`: the robot at its control rate, one column per row of the
  `_channels.tsv` beside it: each joint's measured angle (JNTANG, degrees; a prismatic joint in metres), speed,
  torque sent and reference (MISC), the person-robot interaction force and the person's wrench at the hand where
  the session had them (MISC), the hand's position in the robot's base frame (POS, metres). Other tracking systems
  are instruments at their own rate (a joint encoder, a force-torque sensor).
- `*_events.tsv`: each target shown and reached, each safety event and stop (rule, joint, value, limit), with HED
  tags; onsets in seconds from the motion files' first sample.
- `derivatives/rehabkit/`: per session, the outcome measures (range of motion per joint, SPARC, path-length ratio,
  time to target, assistance ratio, peak interaction force) with their units; the profile's ranges beside them.
"""
