"""What ``rehabkit run`` prints about a finished run: verdicts, safety events, contacts, outcomes, files."""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

OUTCOMES = ("reaches_completed", "sparc", "path_length_ratio", "time_to_target_s", "assistance_ratio",
            "peak_interaction_force_n")


def run_report(s: dict[str, Any], out: Path) -> str:
    """The lines for a run whose ``summary.json`` holds ``s``, written to ``out``."""
    m = s["metrics"]
    lines = [f"{s['name']}: {m['sim_time_s']:.3f} s simulated in {m['wall_time_s']:.3f} s "
             f"(real-time factor {m['real_time_factor']:.1f})", *verdict_lines(s)]
    if m.get("reaches"):
        lines.append("  outcomes: " + ", ".join(f"{k} {m[k]:.3g}" for k in OUTCOMES if m.get(k) is not None))
    lines += [f"{name}:\n{text}" for name, text in s.get("reports", {}).items()]
    lines.append(wrote(s, out))
    return "\n".join(lines)


def verdict_lines(s: dict[str, Any]) -> list[str]:
    """What decides a run's exit code and why, from its summary: the verdicts, the task's end, tracking, safety
    events and what the stop achieved, interventions, the link, a latched e-stop, contacts, replaced targets (a
    replay says them as a run does)."""
    m = s["metrics"]
    lines: list[str] = []
    ended = s.get("ended", {"how": "completed"})
    if ended["how"] not in ("completed", "stopped"):  # (cut short: said first, the verdicts after say what it reached)
        lines.append(f"  ENDED   {ended['how']} at {ended.get('t', m['sim_time_s']):.3f} s: {ended['reason']}")
    for e in s["expectations"]:
        value = "missing" if e["value"] is None else f"{e['value']:.6g}"
        lines.append(f"  {'PASS' if e['passed'] else 'FAIL'}  {e['metric']} = {value}  (expected {e['bound']})"
                     + (f"  — {e['reason']}" if e.get("reason") else ""))
    lines += [f"  PLAN    {w['message']}" for w in s["safety"].get("plan_warnings", [])]
    if (task := s.get("task")) and not task["complete"]:  # (said whatever the expectations ask)
        planned = task.get("reaches_planned", task.get("reaches"))
        begun = f", {task['reaches']} begun" if planned and task.get("reaches") != planned else ""
        reaches = f": {task['reaches_completed']} of {planned} reaches completed{begun}" if planned else ""
        lines.append(f"  TASK    incomplete: the plan ends at {task['plan_end_s']:.4g} s, the run at "
                     f"{task['run_s']:g} s ({task['run_s'] / task['plan_end_s']:.1%} of it run){reaches}")
    if why := s.get("tracking"):  # (said whatever the expectations ask, as the task's end is)
        lines.append(f"  TRACKING {why['joint']} followed its reference to {why['rms']:.3g} {why['unit']} rms "
                     f"({why['max']:.3g} {why['unit']} at most, t={why['t_max']:.3f} s): {'; '.join(why['causes'])}")
    lines += [f"  SAFETY  {ev['message']}" for ev in s["safety"]["events"]]
    lines += _stop_outcome(m)
    lines += _interventions(s["safety"].get("interventions", []), s["safety"]["events"])
    lines += _link(m)
    if latch := s["safety"].get("estop_latched"):  # (a run that latched it says so: the next one is refused)
        lines.append(f"  LATCHED the robot's e-stop ({latch}) stays latched: deal with its cause, then a person clears "
                     f"it (`rehabkit estop clear {latch} --by NAME`) before the next run")
    if contacts := int(m.get("contact_steps") or 0):  # e.g. an arm lying on the floor, which nothing else says
        first = s["safety"].get("first_contact")
        lines.append(f"  CONTACT the robot touched something in {contacts} control steps (the floor is the "
                     "plane z = 0)" + (f"; first {first['text']}" if first else ""))
    for r in (s.get("patient") or {}).get("replaced_targets", []):
        lines.append(f"  PATIENT target '{r['target']}' outside the range of {', '.join(r['joints'])}: replaced by "
                     f"the nearest admissible posture ({r['moved_m'] * 1000:.1f} mm away)")
    return lines


def _stop_outcome(m: dict) -> list[str]:
    """What the stop achieved, where it did not do what its words promise: the robot never at rest, or outside its
    ranges after the trigger (an arm whose drives can't hold it falls through a 'held' stop)."""
    if m.get("stop_category") is None:
        return []
    never = m.get("stop_time_s") is None or m["stop_time_s"] != m["stop_time_s"]  # (NaN, or null in JSON)
    out = m.get("joints_in_range") == 0
    if not (never or out):
        return []
    travel = m.get("stop_distance_deg")
    if never and not out and travel is not None and travel < 1e-6:  # (the run ended at the trigger: a link's fault)
        return ["  STOP    the run ended as the stop began: the robot did not move after the trigger, its rest was "
                "not watched to its end (the robot side held it)"]
    said = ["did not come to rest" if never else f"came to rest after {m['stop_time_s']:.3g} s"]
    if out:
        said.append("left the joints' ranges")
    return [f"  STOP    the robot {' and '.join(said)} after the trigger"
            + (f" (a joint travelled {travel:.3g}° since)" if travel is not None else "")
            + ": the stop could not hold it (its drives' limits against its weight, or a push)"]


def wrote(summary: dict, out: Path) -> str:
    """Every file a run wrote: its summary, its recording, the scenario as run, the safety log, what the backend
    wrote (a CAN trace) and its bag, where it wrote them."""
    names = ["summary.json", *summary.get("outputs", {}).values()]
    names += [summary["bag"]["file"]] if "bag" in summary else []
    files = [str(out / name) for name in dict.fromkeys(names)]
    return "wrote " + ", ".join(files[:-1]) + (" and " if len(files) > 1 else "") + files[-1]


def _interventions(interventions: list[dict], events: list[dict], shown: int = 3) -> list[str]:
    """Counts per rule and joint, then the first few not already said as safety events, in full."""
    if not interventions:
        return []
    groups = Counter((e.get("rule"), e.get("joint")) for e in interventions)
    counts = ", ".join(f"{rule}{' ' + joint if joint else ''} {n}" for (rule, joint), n in groups.most_common())
    said = {e.get("message") for e in events}
    new = [e for e in interventions if e.get("message") not in said]
    out = [f"  INTERVENTIONS {len(interventions)}: {counts}"]
    out += [f"    {e.get('message')}" for e in new[:shown]]
    if len(new) > shown:
        out.append(f"    … {len(new) - shown} more in summary.json (safety.interventions)")
    return out


def _link(m: dict[str, Any]) -> list[str]:
    """A robot link's health when it was not perfect: late ticks, refused states, the bridge holding."""
    said = []
    if m.get("deadline_misses"):
        said.append(f"{int(m['deadline_misses'])} of {int(m.get('link_ticks') or 0)} ticks late (the latest "
                    f"{m.get('tick_lateness_max_ms', float('nan')):.1f} ms)")
    if m.get("states_dropped"):  # (by why: stale ones are the host's own late reading, not an attack)
        why = {k[len("states_dropped_"):].replace("_", " "): int(v) for k, v in m.items()
               if k.startswith("states_dropped_") and v}
        said.append(f"{int(m['states_dropped'])} states dropped (" + ", ".join(
            f"{n} {w}" for w, n in sorted(why.items(), key=lambda x: -x[1])) + ")" if why else
            f"{int(m['states_dropped'])} states dropped")
    if m.get("bridge_stale_holds"):
        said.append(f"the bridge held through {int(m['bridge_stale_holds'])} gaps in the commands")
    if m.get("bridge_hold_at_s") is not None:
        said.append(f"the bridge held the robot at {m['bridge_hold_at_s']:.3f} s")
    return [f"  LINK    {'; '.join(said)}"] if said else []
