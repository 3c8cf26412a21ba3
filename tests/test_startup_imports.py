"""What ``rehabkit run`` does before its loop, kept from growing back: the command line's module imports no pydantic
(the collector's thresholds are set before the core is imported), ``run`` is parsed without the other commands'
modules, a scenario's load imports no difflib (a misspelt name's suggestions), and one scan of the installed
distributions' metadata serves the plugins and the extensions."""

from __future__ import annotations

import json
import subprocess
import sys

from tests.conftest import ROOT, SCENARIOS

OTHER_COMMANDS = ("rehabkit.cli.replay", "rehabkit.cli.bridge", "rehabkit.cli.drives", "rehabkit.cli.estop",
                  "rehabkit.cli.keys", "rehabkit.cli.assess", "rehabkit.cli.safety_report", "rehabkit.bids.commands",
                  "rehabkit.canopen")


def _modules_after(code: str) -> set[str]:
    done = subprocess.run([sys.executable, "-c", f"{code}\nimport json, sys; print(json.dumps(sorted(sys.modules)))"],
                          cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return set(json.loads(done.stdout.splitlines()[-1]))


def test_the_command_line_parses_run_without_the_core_or_the_other_commands():
    loaded = _modules_after("from rehabkit.cli.main import _parse; _parse(['run', 'x.yaml', '--out', 'o'])")
    assert "pydantic" not in loaded and "rehabkit.core.plugins.registry" not in loaded
    assert not [m for m in OTHER_COMMANDS if m in loaded]


def test_a_scenario_loads_without_difflib():
    loaded = _modules_after("from rehabkit.core.scenario.loader import load_scenario; "
                            f"load_scenario({str(SCENARIOS / 'hit_roundtrip.yaml')!r})")
    assert "rehabkit_plugins.robots.hit" in loaded and "difflib" not in loaded


def test_the_plugins_and_the_extensions_share_one_scan_of_the_installed_metadata(monkeypatch):
    from importlib import metadata

    from rehabkit.core.plugins import discovery
    from rehabkit.core.plugins.lifecycle import Extensions
    from rehabkit.core.plugins.registry import load_plugins

    scans = []
    scan = metadata.entry_points
    monkeypatch.setattr(metadata, "entry_points", lambda **params: scans.append(params) or scan(**params))
    monkeypatch.setattr(discovery, "_SCAN", None)
    registry, extensions = load_plugins(), Extensions()
    assert len(scans) == 1
    assert "hit" in registry.names("robot") and "rehab" in extensions.names()
