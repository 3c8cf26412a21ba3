"""What ``rehabkit run`` prints about a finished run: verdicts, safety events, contacts, outcomes, files."""

from __future__ import annotations

from pathlib import Path
from typing import Any

OUTCOMES = ("reaches_completed", "sparc", "path_length_ratio", "time_to_target_s", "assistance_ratio",
            "peak_interaction_force_n")


def run_report(s: dict[str, Any], out: Path) -> str:
    """The lines for a run whose ``summary.json`` holds ``s``, written to ``out``."""
    lines = [f"{s['name']}: {s['sim_time_s']:.3f} s simulated in {s['wall_time_s']:.3f} s "
             f"(real-time factor {s['real_time_factor']:.1f})"]
    for e in s["expectations"]:
        value = "missing" if e["value"] is None else f"{e['value']:.6g}"
        lines.append(f"  {'PASS' if e['passed'] else 'FAIL'}  {e['metric']} = {value}  (expected {e['bound']})"
                     + (f"  — {e['reason']}" if e.get("reason") else ""))
    lines += [f"  PLAN    {w['message']}" for w in s["safety"].get("plan_warnings", [])]
    lines += [f"  SAFETY  {ev['message']}" for ev in s["safety"]["events"]]
    m = s["metrics"]
    if contacts := int(m.get("contact_steps") or 0):  # e.g. an arm lying on the floor, which nothing else says
        lines.append(f"  CONTACT the robot touched something in {contacts} control steps (the floor is the "
                     "plane z = 0)")
    for r in (s.get("patient") or {}).get("replaced_targets", []):
        lines.append(f"  PATIENT target '{r['target']}' outside the range of {', '.join(r['joints'])}: replaced by "
                     f"the nearest admissible posture ({r['moved_m'] * 1000:.1f} mm away)")
    if m.get("reaches"):
        lines.append("  outcomes: " + ", ".join(f"{k} {m[k]:.3g}" for k in OUTCOMES if m.get(k) is not None))
    lines += [f"{name}:\n{text}" for name, text in s.get("reports", {}).items()]
    lines.append(f"wrote {out / 'summary.json'}" + (f" and {out / 'run.rrd'}" if "outputs" in s else ""))
    return "\n".join(lines)
