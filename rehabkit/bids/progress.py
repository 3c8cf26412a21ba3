"""``rehabkit progress DATASET``: each participant's outcome measures across their sessions, as a therapist reads
them — the range of motion of each joint against the profile's ranges, smoothness (SPARC), time to target, the help
the robot gave (assistance ratio) and the peak interaction force — each drawn, and its change from the first session
to the last said in words with its direction. One HTML page, its figures in it (PNG, base64).

It reads the dataset's ``derivatives/rehabkit/`` (:mod:`rehabkit.bids.derivatives`) and ``participants.tsv``.
"""

from __future__ import annotations

import base64
import html
import io
import math
from pathlib import Path
from typing import Any

from rehabkit.bids.derivatives import FOLDER, read_outcomes
from rehabkit.bids.run_folder import ExportError
from rehabkit.bids.tables import read_tsv, write_file

# measure → (title, unit, which way is better: +1 higher, -1 lower, 0 neither; words for up, down)
MEASURES = {
    "sparc": ("Smoothness (SPARC)", "", +1, "smoother", "less smooth"),
    "time_to_target_s": ("Time to target", "s", -1, "slower", "faster"),
    "assistance_ratio": ("Assistance ratio (robot's share of the work)", "", -1, "more help from the robot",
                         "less help from the robot"),
    "peak_interaction_force_n": ("Peak interaction force", "N", 0, "pushing harder against the robot",
                                 "pushing less against the robot"),
    "path_length_ratio": ("Path-length ratio", "", -1, "less straight", "straighter"),
}
STILL = 0.02  # a change within 2 % of the first value (or of the range) is said to be steady


def _num(v: Any) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return float("nan")


def _sessions(rows: list[dict]) -> tuple[list[str], dict[str, list[float]]]:
    """The sessions in order, and each measure's mean per session (over its runs)."""
    order = list(dict.fromkeys(r["session"] for r in rows))
    keys = [k for k in rows[0] if k not in ("task", "run", "acq_time", "session", "sidecar")]
    means: dict[str, list[float]] = {}
    for k in dict.fromkeys(k for r in rows for k in r if k in keys or k.startswith("rom_")):
        vals = []
        for s in order:
            xs = [_num(r.get(k)) for r in rows if r["session"] == s]
            xs = [x for x in xs if math.isfinite(x)]
            vals.append(sum(xs) / len(xs) if xs else float("nan"))
        means[k] = vals
    return order, means


def _change(name: str, unit: str, first: float, last: float, better: int, up: str, down: str, scale: float) -> str:
    if not (math.isfinite(first) and math.isfinite(last)):
        return f"{name}: not measured in the first and the last session"
    delta = last - first
    u = f" {unit}" if unit and unit != "°" else unit
    if abs(delta) <= STILL * max(abs(scale), 1e-9):
        return f"{name}: steady ({first:.3g}{u} → {last:.3g}{u})"
    words = up if delta > 0 else down
    verdict = "" if better == 0 else (" — better" if delta * better > 0 else " — worse")
    return f"{name}: {'rose' if delta > 0 else 'fell'} from {first:.3g}{u} to {last:.3g}{u} ({delta:+.3g}{u}): " \
           f"{words}{verdict}"


def _figure(sessions: list[str], means: dict[str, list[float]], ranges: dict[str, dict]) -> bytes:
    try:
        import matplotlib
    except ImportError as exc:  # (a dev dependency, as the safety report's plots)
        raise ExportError("matplotlib", "not installed: the page's figures are drawn with it",
                          "pip install matplotlib (or pip install -e \".[dev]\")") from exc

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    roms = [k for k in means if k.startswith("rom_")]
    shown = [k for k in ("sparc", "time_to_target_s", "assistance_ratio", "peak_interaction_force_n") if k in means]
    fig, axes = plt.subplots(1 + (len(shown) + 1) // 2, 2, figsize=(10, 3.0 * (1 + (len(shown) + 1) // 2)),
                             squeeze=False)
    x = list(range(len(sessions)))
    ax = plt.subplot2grid(axes.shape, (0, 0), colspan=2, fig=fig)
    axes[0, 0].remove()
    axes[0, 1].remove()
    for i, k in enumerate(roms):
        joint, unit = k.split("_", 2)[2], k.split("_", 2)[1]
        color = f"C{i}"
        ax.plot(x, means[k], "o-", color=color, label=f"{joint} [{unit}]")
        r = ranges.get(joint, {})
        for key, style in (("active_deg", "--"), ("passive_deg", ":")):
            if key in r and unit == "deg":
                ax.axhline(r[key][1] - r[key][0], color=color, ls=style, lw=1)
    ax.set_title("Range of motion per joint (dashed: the profile's active range, dotted: passive)", fontsize=10)
    ax.set_ylabel("range of motion")
    ax.legend(fontsize=8, ncol=min(4, max(1, len(roms))), loc="best")
    for a, k in zip(axes.ravel()[2:], shown):
        title, unit, *_ = MEASURES[k]
        a.plot(x, means[k], "o-", color="k")
        finite = [v for v in means[k] if math.isfinite(v)]
        if finite and max(finite) - min(finite) < 0.05 * max(abs(min(finite)), abs(max(finite)), 1e-9):
            mid, half = (max(finite) + min(finite)) / 2, 0.1 * max(abs(min(finite)), abs(max(finite)), 1e-9)
            a.set_ylim(mid - half, mid + half)  # (a steady measure drawn steady, not its noise magnified)
        a.ticklabel_format(axis="y", useOffset=False)
        a.set_title(title + (f" [{unit}]" if unit else ""), fontsize=10)
    for a in [ax, *axes.ravel()[2:]]:
        a.set_xticks(x, sessions, rotation=30 if len(sessions) > 4 else 0, fontsize=8)
        a.grid(alpha=0.3)
    for a in axes.ravel()[2 + len(shown):]:
        a.remove()
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    return buf.getvalue()


def participant_section(sub: str, rows: list[dict], about: dict[str, str]) -> tuple[str, list[str]]:
    """A participant's part of the page (HTML) and what it says in words."""
    sessions, means = _sessions(rows)
    sidecar = rows[-1].get("sidecar") or {}
    ranges = (sidecar.get("ProfileRanges") or {}).get("Joints", {})
    said: list[str] = []
    if len(sessions) < 2:
        said.append(f"one session ({sessions[0]}): changes are said from the second on")
    else:
        for k in (k for k in means if k.startswith("rom_")):
            joint, unit = k.split("_", 2)[2], k.split("_", 2)[1]
            active = ranges.get(joint, {}).get("active_deg")
            scale = (active[1] - active[0]) if active and unit == "deg" else means[k][0]
            said.append(_change(f"Range of motion, {joint}", "°" if unit == "deg" else "m", means[k][0], means[k][-1],
                                +1, "larger", "smaller", scale)
                        + (f" ({100 * means[k][-1] / scale:.0f} % of the active range)" if active and unit == "deg"
                           and scale > 0 else ""))
        for k, (title, unit, better, up, down) in MEASURES.items():
            if k in means:
                said.append(_change(title, unit, means[k][0], means[k][-1], better, up, down, means[k][0]))
    png = base64.b64encode(_figure(sessions, means, ranges)).decode()
    words = {"profile_id": "profile", "simulated": "simulated by a model:"}
    who = ", ".join(f"{words.get(k, k.replace('_', ' '))} {v}" for k, v in about.items()
                    if v not in ("", "n/a", None) and k != "participant_id")
    head = "<tr><th>measure</th>" + "".join(f"<th>{html.escape(x)}</th>" for x in sessions) + "</tr>"
    order = [*(k for k in MEASURES if k in means), *(k for k in means if k.startswith("rom_")),
             *(k for k in means if k not in MEASURES and not k.startswith("rom_"))]
    table = head + "".join(f"<tr><td>{html.escape(k)}</td>" + "".join(
        f"<td>{v:.3g}</td>" if math.isfinite(v) else "<td>–</td>" for v in means[k]) + "</tr>" for k in order)
    part = (f"<section><h2>{html.escape(sub)}</h2><p class='who'>{html.escape(who)}</p>"
            f"<p>{len(sessions)} session(s), {len(rows)} run(s): first {html.escape(sessions[0])}, last "
            f"{html.escape(sessions[-1])}.</p><ul>" + "".join(f"<li>{html.escape(s)}</li>" for s in said) + "</ul>"
            f"<img alt='{html.escape(sub)}: outcome measures across sessions' src='data:image/png;base64,{png}'>"
            f"<table>{table}</table></section>")
    return part, said


def write_progress(root: Path, participant: str | None = None, out: Path | None = None) -> tuple[Path, list[str]]:
    """The page for every participant (or ``participant``: a label, with or without ``sub-``, or a profile id).
    Returns its path and what it says."""
    if not (root / FOLDER).is_dir():
        raise ExportError(root / FOLDER, "no outcome measures: not a dataset `rehabkit export bids` wrote",
                          "give the folder given to export bids --out")
    everyone = read_outcomes(root)
    about = {r["participant_id"]: r for r in read_tsv(root / "participants.tsv")}
    if participant is not None:
        wanted = {p for p in everyone if participant in (p, p.removeprefix("sub-"))
                  or about.get(p, {}).get("profile_id") == participant}
        if not wanted:
            raise ExportError("--participant", f"'{participant}' is not in {root}",
                              f"give one of {', '.join(p.removeprefix('sub-') for p in everyone) or 'none'}")
        everyone = {p: everyone[p] for p in everyone if p in wanted}
    if not everyone:
        raise ExportError(root, "no runs in the dataset", "add runs with `rehabkit export bids RUN_DIR... --out "
                          f"{root}`")
    import json

    described = root / "dataset_description.json"
    name = json.loads(described.read_text()).get("Name", root.name) if described.exists() else root.name
    parts, said = [], []
    for sub, rows in everyone.items():
        part, words = participant_section(sub, rows, about.get(sub, {}))
        parts.append(part)
        said += [f"{sub}: {w}" for w in words]
    page = ("<!doctype html><html lang='en'><meta charset='utf-8'><title>Progress across sessions</title>"
            "<style>body{font-family:sans-serif;max-width:62em;margin:1em auto;color:#222}"
            "td,th{border:1px solid #ccc;padding:2px 6px;font-size:0.85em}table{border-collapse:collapse}"
            "img{max-width:100%}.who{color:#555}section{margin-bottom:2.5em}</style>"
            f"<h1>Progress across sessions</h1><p>{html.escape(name)}: the outcome measures of each run "
            "(rehabkit's rehab layer), averaged per session.</p>" + "".join(parts) + "</html>\n")
    out = out or root / FOLDER / "progress.html"
    write_file(out, page)
    return out, said
