"""The safety report's pages: a table per skill (simulation, link and CANopen side by side) and a plot of each, as
Markdown and as one self-contained HTML file (plots inline)."""

from __future__ import annotations

import base64
import html
import math
from pathlib import Path

import numpy as np

from rehabkit.core.io import atomic_write_text

ROWS = [  # (label, how to get it from a SkillRun, format)
    ("expectations met", lambda r: "yes" if r.passed else f"NO: {'; '.join(r.failed)}", "{}"),
    ("trigger", lambda r: r.trigger, "{}"),
    ("limit crossed at [s]", lambda r: r.onset_s, "{:.3f}"),
    ("stop triggered at [s]", lambda r: r.trip_s, "{:.3f}"),
    ("reaction time [ms]", lambda r: r.reaction_ms, "{:.1f}"),
    ("stop category / reaction", lambda r: r.category, "{}"),
    ("time to standstill [s]", lambda r: r.figures.get("stop_time_s"), "{:.3f}"),
    ("largest joint travel after the trigger [deg]", lambda r: r.figures.get("stop_distance_deg"), "{:.2f}"),
    ("hand path after the trigger [mm]", lambda r: _mm(r.figures.get("stop_distance_m")), "{:.1f}"),
    ("fastest joint after the trigger [deg/s]", lambda r: r.figures.get("stop_peak_speed_deg_s"), "{:.1f}"),
    ("largest prismatic joint travel after the trigger [mm]", lambda r: _mm(r.figures.get("stop_joint_travel_m")),
     "{:.1f}"),
    ("fastest prismatic joint after the trigger [mm/s]", lambda r: _mm(r.figures.get("stop_joint_peak_speed_m_s")),
     "{:.1f}"),
    ("peak interaction force [N]", lambda r: r.figures.get("ft_peak_force_n",
                                                           r.figures.get("peak_interaction_force_n")), "{:.1f}"),
    ("peak force after the trigger [N]", lambda r: r.figures.get("force_after_trip_peak_n"), "{:.1f}"),
    ("time above the force limit after the trigger [s]", lambda r: r.figures.get("force_above_limit_s"), "{:.3f}"),
    ("joints stayed in range after the trigger", lambda r: _yes(r.figures.get("joints_in_range")), "{}"),
    ("force sensor bias tared [N]", lambda r: r.figures.get("ft_bias_n"), "{:.2f}"),
    ("force sensor noise raw / filtered [N]", lambda r: _pair(r.figures, "ft_noise_n", "ft_noise_filtered_n"), "{}"),
    ("ramp-in [s]", lambda r: r.figures.get("ramp_in_s"), "{:g}"),
    ("largest torque rate [N·m/s]", lambda r: r.figures.get("torque_rate_max_nm_s"), "{:.0f}"),
    ("notes", lambda r: "; ".join(r.notes) or None, "{}"),
]


def _yes(v):
    return None if v is None else ("yes" if v == 1.0 else "NO")


def _mm(v):
    return None if v is None or not math.isfinite(v) else 1e3 * v


def _pair(f: dict, a: str, b: str):
    return f"{f[a]:.3f} / {f[b]:.3f}" if a in f and b in f else None


def _cell(run, get, fmt) -> str:
    if run is None:
        return "n/a"
    v = get(run)
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    return fmt.format(v)


STYLES = ("-", "--", ":")
LABELS = {"simulation": "simulation", "link": "link", "canopen": "CANopen"}


def _plot(runs: tuple, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 4.2), sharex=True)
    for run, style in zip(runs, STYLES, strict=False):
        if run is None:
            continue
        tr = run.trace
        top.plot(tr.t, np.degrees(np.abs(tr.qd)).max(axis=1), style, label=run.backend)
        if tr.f_h is not None:
            bottom.plot(tr.t, tr.f_h, style, label=run.backend)
        else:
            bottom.plot(tr.t, np.abs(tr.tau).max(axis=1), style, label=f"{run.backend} (largest |τ|, N·m)")
        if run.trip_s is not None:
            for ax in (top, bottom):
                ax.axvline(run.trip_s, color="red", lw=0.8, ls=style)
    top.set_ylabel("fastest joint [deg/s]")
    bottom.set_ylabel("force [N] (or largest |τ| [N·m])" if any(
        r is not None and r.trace.f_h is None for r in runs) else "interaction force [N]")
    bottom.set_xlabel("time [s]")
    top.legend(loc="upper left", fontsize=8)
    top.set_title(next(r for r in runs if r is not None).scenario, fontsize=10)
    # fixed margins, not tight_layout(): it measures every tick label to place the axes, a third of a plot's time,
    # and these plots are all laid out alike (room for a 5-character tick label and the axis label at the left)
    fig.subplots_adjust(left=0.12, right=0.975, top=0.918, bottom=0.139, hspace=0.13)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def write_report(runs: list, out: Path, backends: tuple[str, ...] = ("simulation", "link", "canopen")) \
        -> tuple[Path, Path]:
    """``out/safety_report.md`` and ``out/safety_report.html`` (plots as PNGs beside the Markdown, inline in the
    HTML); ``runs``: a run per backend of ``backends`` per skill (None where it does not apply)."""
    out.mkdir(parents=True, exist_ok=True)
    heads = [LABELS.get(b, b) for b in backends]
    how = {"simulation": "in simulation (MuJoCo)", "link": "over the robot link (lock-step UDP to a bridge driving the "
           "robot's MuJoCo model)", "canopen": "on CANopen (simulated CiA 402 drives on the robot's MuJoCo model, "
           "lock-step bus, at the highest of 1000, 500, 250 Hz the bus arithmetic allows)"}
    ways = [how.get(b, b) for b in backends]
    said = ", ".join(ways[:-1]) + (" and " if len(ways) > 1 else "") + ways[-1]
    md = [f"# Safety skills: {', '.join(heads)}", "",
          f"Each skill's scenario run {said}. Reaction: from the limit's first crossing in truth to the stop.", ""]
    page = ["<!doctype html><meta charset='utf-8'><title>rehabkit safety report</title>",
            "<style>body{font-family:sans-serif;max-width:70em}td,th{border:1px solid #ccc;padding:2px 8px}"
            "table{border-collapse:collapse;margin-bottom:1em}</style>",
            f"<h1>Safety skills: {html.escape(', '.join(heads))}</h1>"]
    for row in runs:
        name = next(r for r in row if r is not None).scenario
        png = out / f"{name}.png"
        _plot(row, png)
        md += [f"## {name}", "", "| | " + " | ".join(heads) + " |", "|---|" + "---|" * len(heads)]
        page += [f"<h2>{html.escape(name)}</h2><table><tr><th></th>"
                 + "".join(f"<th>{html.escape(h)}</th>" for h in heads) + "</tr>"]
        for label, get, fmt in ROWS:
            cells = [_cell(run, get, fmt) for run in row]
            if all(c in ("–", "n/a") for c in cells):
                continue
            md.append(f"| {label} | " + " | ".join(cells) + " |")
            page.append(f"<tr><td>{html.escape(label)}</td>" + "".join(f"<td>{html.escape(c)}</td>" for c in cells)
                        + "</tr>")
        md += ["", f"![{name}]({png.name})", ""]
        data = base64.b64encode(png.read_bytes()).decode()
        page += ["</table>", f"<img alt='{html.escape(name)}' src='data:image/png;base64,{data}'>"]
    md_path, html_path = out / "safety_report.md", out / "safety_report.html"
    atomic_write_text(md_path, "\n".join(md) + "\n")
    atomic_write_text(html_path, "\n".join(page) + "\n")
    return md_path, html_path
