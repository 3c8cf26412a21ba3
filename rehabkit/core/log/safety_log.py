"""A tamper-evident record of a run's safety: what was in force and what the safety layer did, as JSON lines whose
hashes chain them (``safety_log.jsonl`` in the run's folder; ``rehabkit audit RUN_DIR`` checks and prints it).

Each record carries the hash of the one before it and its own: SHA-256 over the previous hash and the record's
canonical JSON — or, with ``REHABKIT_AUDIT_KEY`` set, HMAC-SHA256 under that key. Without a key an edit shows unless
every later hash is recomputed too (keep the last hash, printed at the end of a run, somewhere else, e.g. the lab
notebook); with a key, recomputing them needs the key.

The records: the run (software version, the scenario as it ran and its SHA-256, the plugins with their packages'
versions, the patient's id, the backend), every limit in force with where it came from, each intervention, the end.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from rehabkit.core.io import atomic_write_text

LOG = "safety_log.jsonl"
KEY_ENV = "REHABKIT_AUDIT_KEY"
GENESIS = "0" * 64


def _canonical(body: dict[str, Any]) -> bytes:
    return json.dumps(body, sort_keys=True, separators=(",", ":"), ensure_ascii=False, default=float).encode()


def _digest(prev: str, body: dict[str, Any], key: bytes | None) -> str:
    data = prev.encode() + _canonical(body)
    return hmac.new(key, data, hashlib.sha256).hexdigest() if key else hashlib.sha256(data).hexdigest()


def audit_key() -> bytes | None:
    """The key in ``REHABKIT_AUDIT_KEY``, if one is set."""
    key = os.environ.get(KEY_ENV)
    return key.encode() if key else None


def chain(records: list[dict[str, Any]], key: bytes | None = None) -> str:
    """The records as hash-chained JSON lines (``seq``, ``prev`` and ``hash`` added to each)."""
    lines, prev = [], GENESIS
    for seq, record in enumerate(records):
        body = {"seq": seq, "prev": prev, **record}
        prev = _digest(prev, body, key)
        lines.append(json.dumps({**body, "hash": prev}, ensure_ascii=False, default=float))
    return "\n".join(lines) + "\n"


def verify(path: Path, key: bytes | None = None) -> tuple[list[dict[str, Any]], list[str]]:
    """The records of a log and what is wrong with its chain (nothing: intact)."""
    records, problems, prev = [], [], GENESIS
    for number, line in enumerate(Path(path).read_text().splitlines(), start=1):
        try:
            record = json.loads(line)
            body = {k: v for k, v in record.items() if k != "hash"}
            stated = record["hash"]
        except (ValueError, KeyError, AttributeError):
            problems.append(f"line {number}: not a record of this log")
            continue
        what = f"record {record.get('seq', '?')} ({record.get('kind', '?')}, line {number})"
        if record.get("prev") != prev:
            problems.append(f"{what}: does not follow the record before it (one removed, inserted or reordered)")
        if _digest(record.get("prev", ""), body, key) != stated:
            problems.append(f"{what}: its content does not match its hash (edited"
                            f"{', or checked without the key it was written with' if key is None else ''})")
        records.append(record)
        prev = stated
    if not records:
        problems.append("the log holds no records")
    return records, problems


def joint_limits(lim: Any, j: int, revolute: bool, narrowed_by: dict) -> dict[str, Any]:
    """Joint ``j``'s limits in its own units: degrees and N·m for a revolute joint, metres and N for a prismatic."""
    if revolute:
        return {"lower_deg": round(float(np.degrees(lim.lower[j])), 6), "upper_deg": round(float(np.degrees(
            lim.upper[j])), 6), "velocity_deg_s": round(float(np.degrees(lim.velocity[j])), 6),
            "effort_nm": round(float(lim.effort[j]), 6), "narrowed_by": narrowed_by}
    return {"lower_m": round(float(lim.lower[j]), 6), "upper_m": round(float(lim.upper[j]), 6),
            "velocity_m_s": round(float(lim.velocity[j]), 6), "effort_n": round(float(lim.effort[j]), 6),
            "narrowed_by": narrowed_by}


def kind_settings(safety: Any, revolute: np.ndarray) -> dict[str, Any]:
    """The envelope's settings for every joint of a kind, for the kinds the robot has: how far beyond its range a
    joint trips and a controlled stop's deceleration bound (None: each drive's own) — a revolute joint's in degrees,
    a prismatic joint's in metres."""
    out: dict[str, Any] = {}
    if np.any(revolute):
        out.update(position_margin_deg=safety.position_margin_deg, stop_decel_deg_s2=safety.stop_decel_deg_s2)
    if not np.all(revolute):
        out.update(position_margin_m=safety.position_margin_m, stop_decel_m_s2=safety.stop_decel_m_s2)
    return out


def run_records(a: Any, scenario_text: str, summary: dict[str, Any]) -> list[dict[str, Any]]:
    """The records of a finished run (``a``: its :class:`~rehabkit.core.setup.assembly.Assembly`)."""
    sc, patient = a.sc, summary.get("patient") or {}  # (the rehab layer's section says who the run was for)
    used = summary["plugins"]  # (results.plugin_versions: kind → type, package, version; sensors by name)
    plugins = {f"{kind}:{p['type']}": f"{p['package']} {p['version']}" for kind, p in used.items() if kind != "sensors"}
    plugins.update({f"sensor:{p['type']}": f"{p['package']} {p['version']}" for p in used["sensors"].values()})
    model, lim = a.robot.model, a.limits
    sources = a.limit_sources.as_dict()
    joints = {name: joint_limits(lim, j, turns, sources.get(name, {}))
              for j, (name, turns) in enumerate(zip(model.joint_names, model.revolute, strict=True))}
    safety = a.safety.config
    records = [
        {"kind": "run", "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
         "software": {"rehabkit": summary["rehabkit_version"]},
         "scenario": {"file": str(a.loaded.path), "sha256": hashlib.sha256(scenario_text.encode()).hexdigest()},
         "plugins": plugins, "patient": patient.get("id"), "backend": sc.backend.type,
         **({"link": link} if (link := a.backend.provenance()) else {}),
         "seed": sc.seed, "keyed": audit_key() is not None},
        {"kind": "limits", "joints": joints, **kind_settings(safety, model.revolute),
         "interaction_force_n": safety.interaction_force_n,
         "keep_in": safety.keep_in.model_dump(mode="json") if safety.keep_in is not None else None,
         "stop": model.safe_stop, "stop_category": a.safety.categories,
         "brakes_nm": model.brakes.tolist() if model.brakes is not None else None,
         "stop_after_s": safety.stop_after_s},
        *({"kind": "intervention", **event} for event in summary["safety"]["interventions"]),
        {"kind": "end", "passed": summary.get("passed"), "safety_events": summary["metrics"].get("safety_events"),
         "sim_time_s": summary["metrics"].get("sim_time_s")},
    ]
    return records


def write(path: Path, records: list[dict[str, Any]]) -> str:
    """Write the chained log whole (temp file, then rename); returns the last record's hash."""
    text = chain(records, audit_key())
    atomic_write_text(path, text)
    return json.loads(text.splitlines()[-1])["hash"]
