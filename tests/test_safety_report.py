"""rehabkit safety-report: every safety skill in simulation and over the link, side by side."""

from __future__ import annotations

import re

import numpy as np

from rehabkit.cli import main
from tests.conftest import ROOT


def _row(section: str, label: str) -> list[str]:
    line = next(x for x in section.splitlines() if x.startswith(f"| {label} |"))
    return [c.strip() for c in line.strip("|").split("|")][1:]


def test_the_report_gives_every_skill_in_simulation_and_over_the_link(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(ROOT)  # (the README's command: the skills in scenarios/safety/)
    assert main(["safety-report", "--out", str(tmp_path / "report")]) == 0
    md = (tmp_path / "report" / "safety_report.md").read_text()
    sections = dict(re.findall(r"^## (\S+)\n(.*?)(?=^## |\Z)", md, re.S | re.M))
    assert set(sections) == {"hit-estop", "hit-force", "hit-force-yield", "hit-link-loss", "hit-ramp-in", "hit-range",
                             "hit-speed", "lexos-force", "lexos-force-yield", "lexos-spastic-catch"}
    # a person as the force's source: the MyoArm's spastic elbow flexors catch a fast passive extension; the robot
    # yields and the cuff force stays at the limit (a stop and hold lets it reach ~40 N); simulation only
    catch = sections["lexos-spastic-catch"]
    assert _row(catch, "stop category / reaction") == ["yield", "n/a"]
    assert float(_row(catch, "peak force after the trigger [N]")[0]) <= 1.1 * 25
    assert "simulation only" in _row(catch, "notes")[0]
    for name, limit in (("hit-force-yield", 30.0), ("lexos-force-yield", 25.0)):  # a reaction that limits the force
        assert _row(sections[name], "stop category / reaction") == ["yield", "yield"]
        assert all(float(f) <= 1.1 * limit for f in _row(sections[name], "peak force after the trigger [N]"))
        assert _row(sections[name], "joints stayed in range after the trigger") == ["yes", "yes"]
        # the rig's spring force (from where the mount went) reaching the limit, to the trip: the filter's lag
        assert all(0 <= float(r) < 25 for r in _row(sections[name], "reaction time [ms]"))
    for name in ("hit-force", "lexos-force"):  # the force limit: the same force, the rig's push, both ways
        sim, link = (float(c.split(": ")[-1].split()[0]) for c in _row(sections[name], "trigger"))  # "…: 30.03 (…"
        assert abs(sim - link) < 0.1
        assert all(0 < float(r) < 15 for r in _row(sections[name], "reaction time [ms]"))  # the filter's lag
        for raw_filtered in _row(sections[name], "force sensor noise raw / filtered [N]"):  # (0.3 N simulated)
            raw, filtered = (float(v) for v in raw_filtered.split(" / "))
            assert 0.25 < raw < 0.35 and filtered < raw / 3
    bias = [float(v) for v in _row(sections["lexos-force"], "force sensor bias tared [N]")]
    assert all(abs(b - float(np.linalg.norm([-1.2, 2.1, 0.7]))) < 0.1 for b in bias)  # lexos_force.yaml's offset
    for name in ("hit-range", "hit-speed", "hit-estop"):  # a stop is measured the same on both backends
        a, b = (float(v) for v in _row(sections[name], "largest joint travel after the trigger [deg]"))
        assert abs(a - b) < 0.2
    assert "refused: e-stop latched" in _row(sections["hit-estop"], "notes")[0]
    sim, link = _row(sections["hit-link-loss"], "reaction time [ms]")
    assert sim == "n/a" and 5 <= float(link) <= 15  # the bridge's own hold, 10 ms after the last command
    assert all(r == "yes" for s in sections.values() for r in _row(s, "expectations met") if r != "n/a")
    html = (tmp_path / "report" / "safety_report.html").read_text()
    assert html.count("data:image/png;base64,") == 10 and "<table>" in html
