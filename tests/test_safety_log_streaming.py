"""The safety log written as the run goes (issue 48): a run killed on the way leaves a log valid up to its last record,
each trip on disk before the safety layer acts on it; `rehabkit audit` checks such a log to where it ends, says it
ends without its closing record and leaves out a torn last line; a run refused before it ran leaves none."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from rehabkit.core.log import safety_log
from rehabkit.core.log.safety_log import LOG, SafetyLog, chain, check
from rehabkit.core.run import session as session_module
from rehabkit.core.run.runner import Runner
from rehabkit.core.safety.event import SafetyEvent
from rehabkit.core.safety.stopping import Stopping
from rehabkit.core.scenario.loader import load_scenario
from rehabkit.core.setup.assembly import SetupError
from tests.conftest import ROOT, SCENARIOS
from tests.test_cli import cli

RANGE = SCENARIOS / "safety" / "hit_range.yaml"  # a push drives the HIT out of its range: a trip at ~0.75 s


def _records(path):
    return [json.loads(line) for line in path.read_text().splitlines()]


def _wait_for(predicate, what: str, proc=None, deadline_s: float = 120.0):
    """Poll until ``predicate()`` holds: a killed run's file, written by another process, is all there is to watch (the
    poll's pause is not a synchronisation; the predicate is)."""
    deadline = time.monotonic() + deadline_s
    while time.monotonic() < deadline:
        found = predicate()
        if found:
            return found
        if proc is not None and proc.poll() is not None:
            pytest.fail(f"the run ended (exit {proc.returncode}) before {what}: {proc.stderr.read()}")
        time.sleep(0.001)
    pytest.fail(f"no {what} within {deadline_s} s")


def _trip_on_disk(log):
    def found():
        if not log.exists():
            return None
        for line in log.read_text().split("\n")[:-1]:  # complete lines only
            record = json.loads(line)
            if record.get("kind") == "intervention" and "category" in record.get("data", {}):
                return record
        return None
    return found


def test_a_run_killed_after_its_trip_leaves_a_log_audit_checks_up_to_the_trip(tmp_path):
    out = tmp_path / "killed"
    # the stop simulated long after the trip (seconds of wall clock): the kill lands while the run goes
    proc = subprocess.Popen([sys.executable, "-m", "rehabkit.cli", "run", str(RANGE), "--out", str(out),
                             "--set", "duration=60", "--set", "safety.stop_after_s=60", "--set", "logging.rrd=false"],
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        trip = _wait_for(_trip_on_disk(out / LOG), "trip record on disk", proc)
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.kill()
        proc.wait(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    assert not (out / "summary.json").exists()  # (killed: no finish)
    records = _records(out / LOG)
    assert [r["kind"] for r in records] == ["run", "limits", "intervention"]  # (nothing after the trip: killed)
    assert records[-1] == trip and trip["rule"] == "position" and trip["data"]["category"] == 2
    assert records[0]["scenario"]["file"].endswith("hit_range.yaml") and records[1]["joints"]["elbow_2"]
    done = cli("audit", str(out))
    assert done.returncode == 0, done.stderr
    log = check(out / LOG)  # what the audit read: unfinished, intact up to its last record (2, the trip)
    assert (log.finished, [r["seq"] for r in log.records], log.torn, log.problems) == (False, [0, 1, 2], None, [])
    assert "chain intact: 3 records (up to where it ends)" in done.stdout  # (and says so)
    # a torn last line (a write cut short) is left out, said so; the chain still holds
    with (out / LOG).open("a") as f:
        f.write('{"seq": 3, "prev": "' + records[-1]["hash"][:20])
    done = cli("audit", str(out))
    log = check(out / LOG)
    assert done.returncode == 0 and log.torn is not None and (len(log.records), log.problems) == (3, [])
    assert "cut short" in done.stdout  # (and says so)
    # an edit to a killed run's log is found as in a finished one's
    lines = (out / LOG).read_text().split("\n")
    lines[2] = lines[2].replace("elbow_2", "elbow_1")
    (out / LOG).write_text("\n".join(lines))
    done = cli("audit", str(out))
    assert done.returncode == 1 and [(p.line, p.fault) for p in check(out / LOG).problems] == [(3, "edited")]


def test_the_trip_is_on_disk_before_the_stop_begins(tmp_path, monkeypatch):
    order = []
    log = tmp_path / "run" / LOG
    real_fsync, real_begin = os.fsync, Stopping.begin

    def fsync(fd):
        real_fsync(fd)
        if log.exists():  # what the log holds once synced: a trip among it?
            order.append(("fsync", sum('"category"' in line for line in log.read_text().splitlines())))

    def begin(self, t, category, q, qd):
        order.append(("begin", t))
        real_begin(self, t, category, q, qd)

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(Stopping, "begin", begin)
    result = Runner(load_scenario(RANGE, {"logging": {"rrd": False}}), out_dir=tmp_path / "run").run()
    (event,) = result.summary["safety"]["events"]
    first_begin = next(i for i, (what, _) in enumerate(order) if what == "begin")
    assert order[first_begin] == ("begin", event["t"])
    assert order[first_begin - 1] == ("fsync", 1)  # synced with the trip in it, right before the stop began
    records = _records(log)
    assert [r["kind"] for r in records] == ["run", "limits", "intervention", "end"]
    assert result.summary["safety_log_hash"] == records[-1]["hash"] and check(log).finished


def test_a_run_refused_before_it_ran_leaves_no_log(tmp_path, monkeypatch):
    def refused(s):  # a trip written to the log, then the setup refuses the run
        s.safety.trip(0.0, s.q0, "plan", "refused for the test")
        assert '"refused for the test' in (tmp_path / "run" / LOG).read_text()
        raise SetupError("refused for the test")

    monkeypatch.setattr(session_module, "_first_plan", refused)
    with pytest.raises(SetupError):
        Runner(load_scenario(RANGE, {"logging": {"rrd": False}}), out_dir=tmp_path / "run").run()
    assert not (tmp_path / "run" / LOG).exists()


class _Layer:
    """What the log reads of a safety layer: its interventions, and a clipping episode that may still grow."""

    def __init__(self):
        self.interventions, self.growing = [], None


def _event(t, rule, level="INFO", **data):
    return SafetyEvent(t, rule, None, None, None, f"t={t:.3f}s: {rule}", data, level=level)


def test_routine_records_are_batched_and_a_clipping_episode_waits_until_it_is_over(tmp_path):
    layer = _Layer()
    path = tmp_path / LOG
    # (the interval's flushes made here, one by one: the flusher thread's own interval is an hour)
    log = SafetyLog(path, layer, [{"kind": "run"}, {"kind": "limits"}], flush_s=3600.0)
    try:
        layer.interventions.append(_event(0.0, "ramp-in"))
        log.flush_routine()
        assert len(_records(path)) == 3  # the ramp-in record written by the interval's flush
        clip = _event(0.5, "torque-clip", "WARN", steps=1)
        layer.interventions.append(clip)
        layer.growing = clip
        layer.interventions.append(_event(0.6, "ramp-out"))
        for _ in range(5):  # five flushes, in which nothing may be written
            log.flush_routine()
        assert len(_records(path)) == 3  # (the episode may still grow: it and what follows it wait)
        clip.data["steps"] = 40  # (it grows)
        layer.interventions.append(trip := _event(0.7, "position", "ERROR", category=2))
        log.tripped(trip)  # everything before the trip, and the trip, on disk now
        kinds = [(r["kind"], r.get("rule")) for r in _records(path)]
        assert kinds[2:] == [("intervention", "ramp-in"), ("intervention", "torque-clip"), ("intervention", "ramp-out"),
                             ("intervention", "position")]
        assert _records(path)[3]["data"]["steps"] == 40
        last = log.close([_event(0.8, "stale-command", "WARN")],
                         {"passed": False, "metrics": {"safety_events": 1, "sim_time_s": 1.0}})
    except BaseException:
        log.discard()
        raise
    records = _records(path)
    assert [r.get("rule", r["kind"]) for r in records[-2:]] == ["stale-command", "end"]
    assert records[-1]["hash"] == last
    # the same chain as the log written whole
    assert path.read_text() == chain([{k: v for k, v in r.items() if k not in ("seq", "prev", "hash")}
                                      for r in records])
    assert check(path).finished and check(path).problems == []


def test_a_disk_that_refuses_a_write_does_not_hold_up_the_stop_and_the_finish_writes_the_log_whole(tmp_path,
                                                                                                     monkeypatch):
    layer = _Layer()
    path = tmp_path / LOG
    log = SafetyLog(path, layer, [{"kind": "run"}])
    real_write = os.write

    def full(fd, data):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(safety_log.os, "write", full)
    layer.interventions.append(trip := _event(0.7, "position", "ERROR", category=2))
    log.tripped(trip)  # (no error: the stop goes on)
    monkeypatch.setattr(safety_log.os, "write", real_write)
    log.close([], {"passed": False, "metrics": {}})
    assert [r.get("rule", r["kind"]) for r in _records(path)] == ["run", "position", "end"]
    assert check(path).problems == []
