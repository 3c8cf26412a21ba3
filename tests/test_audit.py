"""The tamper-evident safety log: a run writes it, `rehabkit audit` checks its chain and shows an edited,
removed or re-chained record (issue 19, part 3)."""

from __future__ import annotations

import json

import pytest

from rehabkit.core.log.safety_log import LOG, chain, check, verify
from tests.conftest import SCENARIOS
from tests.test_cli import cli


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("audited")
    done = cli("run", str(SCENARIOS / "hit_roundtrip.yaml"), "--out", str(out), "--set", "duration=0.5",
               "--set", "safety.ramp_in_s=0.2")
    assert done.returncode in (0, 1), done.stderr
    return out


def _records(run_dir):
    return [json.loads(line) for line in (run_dir / LOG).read_text().splitlines()]


def test_a_run_leaves_an_intact_chain_of_what_was_in_force_and_what_happened(run_dir):
    records = _records(run_dir)
    assert [r["kind"] for r in records] == ["run", "limits", "intervention", "end"]
    first = records[0]
    assert first["software"]["rehabkit"] and len(first["scenario"]["sha256"]) == 64
    assert first["plugins"]["robot:hit"].startswith("rehabkit ") and first["backend"] == "mujoco"
    assert records[1]["joints"]["elbow_2"]["effort_nm"] == 25.0 and records[2]["rule"] == "ramp-in"
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["safety_log_hash"] == records[-1]["hash"]
    done = cli("audit", str(run_dir))
    assert done.returncode == 0 and "chain intact: 4 records" in done.stdout and "ramp-in" in done.stdout


def test_an_edited_or_removed_record_is_found(run_dir, tmp_path):
    lines = (run_dir / LOG).read_text().splitlines()
    edited = tmp_path / "edited"
    edited.mkdir()
    (edited / LOG).write_text("\n".join([*lines[:2], lines[2].replace("0.2 s", "0.1 s"), lines[3]]) + "\n")
    done = cli("audit", str(edited))
    assert done.returncode == 1  # (its words: tests/test_message_wording.py)
    found = [(p.line, p.seq, p.kind, p.fault) for p in check(edited / LOG).problems]
    assert found == [(3, 2, "intervention", "edited")]
    removed = tmp_path / "removed"
    removed.mkdir()
    (removed / LOG).write_text("\n".join([*lines[:2], lines[3]]) + "\n")
    done = cli("audit", str(removed))
    assert done.returncode == 1
    assert [(p.line, p.seq, p.fault) for p in check(removed / LOG).problems] == [(3, 3, "out-of-order")]
    assert cli("audit", str(tmp_path)).returncode == 2  # no log at all


def test_with_a_key_a_rechained_log_is_found_too(monkeypatch, tmp_path):
    records = [{"kind": "run"}, {"kind": "intervention", "message": "t=1.000s: velocity above its limit"}]
    monkeypatch.setenv("REHABKIT_AUDIT_KEY", "the lab's secret")
    (tmp_path / LOG).write_text(chain(records, b"the lab's secret"))
    assert verify(tmp_path / LOG, b"the lab's secret")[1] == []
    records[1]["message"] = "nothing happened"
    (tmp_path / LOG).write_text(chain(records))  # edited and every hash recomputed, without the key
    done = cli("audit", str(tmp_path))
    assert done.returncode == 1
    assert [(p.line, p.fault, p.keyed) for p in check(tmp_path / LOG, b"the lab's secret").problems] == [
        (1, "edited", True), (2, "edited", True)]
