"""``participants.tsv`` and its sidecar: each participant from their patient profile — the pseudonymous id, the
treated side, the impairment and its scale, the segment lengths, and the model that stood in for them in a simulated
session — and nothing else about a person."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from rehabkit.bids.run_folder import RunFolder
from rehabkit.bids.tables import read_tsv, write_json, write_tsv

DESCRIBED = {
    "participant_id": {"Description": "the participant's label: their profile's pseudonymous id, its letters and "
                                      "digits (a sweep's simulated people: the profile's id, s and the seed)"},
    "profile_id": {"Description": "the patient profile's id, as the profile writes it"},
    "side": {"Description": "the treated side", "Levels": {"left": "left", "right": "right"}},
    "impairment": {"Description": "what is treated (the profile's impairment.condition)"},
    "impairment_scale": {"Description": "the clinical scale the impairment was scored on"},
    "impairment_score": {"Description": "the participant's score on that scale"},
    "simulated": {"Description": "the model that stood in for the person in a simulated session (a patient plugin: "
                                 "simulated-arm, musculoskeletal); n/a for a person"},
}


def participant_row(sub: str, run: RunFolder) -> dict[str, Any]:
    p = run.profile or {}
    impairment = p.get("impairment") or {}
    model = (p.get("model") or {}).get("type") if run.simulated else None
    row: dict[str, Any] = {"participant_id": sub, "profile_id": p.get("id"), "side": p.get("side"),
                           "impairment": impairment.get("condition"), "impairment_scale": impairment.get("scale"),
                           "impairment_score": impairment.get("score"), "simulated": model}
    for name, length in (p.get("segments") or {}).items():
        row[f"{name}_length"] = length
    return row


def write_participants(root: Path, sub: str, row: dict[str, Any]) -> None:
    """``row`` in ``participants.tsv`` (replacing the participant's, where there is one: the latest profile), the
    sidecar describing every column."""
    path = root / "participants.tsv"
    rows = {r["participant_id"]: r for r in read_tsv(path)}
    rows[sub] = {**rows.get(sub, {}), **{k: v for k, v in row.items() if v is not None or k not in rows.get(sub, {})}}
    columns = list(dict.fromkeys(["participant_id", *DESCRIBED, *(k for r in rows.values() for k in r)]))
    sidecar = path.with_suffix(".json")
    described = json.loads(sidecar.read_text()) if sidecar.exists() else {}
    described |= {k: v for k, v in DESCRIBED.items() if k != "participant_id"}
    for c in columns:
        if c.endswith("_length"):
            described[c] = {"Description": f"the profile's {c.removesuffix('_length').replace('_', ' ')} segment "
                                           "length (the robot adapts to it)", "Units": "m"}
    write_json(sidecar, described)
    write_tsv(path, columns, sorted(rows.values(), key=lambda r: r["participant_id"]))
