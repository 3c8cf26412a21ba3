"""``rehabkit audit RUN_DIR``: check a run's safety log (its hash chain) and print it.

A run killed on the way (SIGKILL, the power gone) leaves a log written up to its last record: the chain is checked
that far and the log said to end without its closing record; a last line cut short as it was written is left out,
said so. Exit 0 when the chain holds, 1 when it does not (tampered), 2 without a log.

``rehabkit recover RUN_DIR``: what a killed run left (kill -9, the power, the OOM killer) made a run folder.

A run killed outright writes no summary and renames nothing: its folder holds the recording as ``run.rrd.tmp``
(Rerun writes it as it goes), the bag as ``.run.mcap.part`` (its messages so far, without the index an MCAP file ends
with), and the safety log without its closing record. Recovering:

- the recording renamed ``run.rrd`` once the Rerun SDK reads it (up to its last whole chunk);
- the bag rewritten whole as ``run.mcap``: every message up to the cut, read in order, written again with its
  schemas, channels, chunks and index (what ``mcap recover`` does);
- the safety log left as it is (``rehabkit audit`` verifies it up to its last record and says it ends unfinished);
- ``summary.json`` computed from what the recording holds — how long the run went, each joint's tracking and range
  of motion at the log rate — and the safety log's trips, marked ``ended: killed (recovered)``; what could not be
  computed again (the task's outcome measures, the verdicts) is said.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import struct
import sys
from pathlib import Path
from typing import Any

import numpy as np

from rehabkit.cli.exits import EXIT_FAILED, EXIT_INVALID, EXIT_OK
from rehabkit.core.log.safety_log import KEY_ENV, LOG, SNAPSHOT, audit_key, check
from rehabkit.core.results.ending import RunEnding


def _link(link: dict | None) -> str:
    """A robot link's record: the bridge, and the session's key id (or that it had none)."""
    if not link:
        return ""
    return f"  link {link.get('bridge')}: " + (f"session {link['session']}, key {link['key_id']}" if "key_id" in link
                                               else str(link.get("session")))


def _line(record: dict) -> str:
    kind = record.get("kind")
    if kind == "run":
        s = record.get("scenario", {})
        return (f"run      {record.get('time')}  rehabkit {record.get('software', {}).get('rehabkit')}  "
                f"{s.get('file')} (sha256 {str(s.get('sha256'))[:12]}…)  patient {record.get('patient')}  "
                f"backend {record.get('backend')}  seed {record.get('seed')}" + _link(record.get("link")))
    if kind == "limits":
        narrowed = {j: list(v["narrowed_by"]) for j, v in record.get("joints", {}).items() if v.get("narrowed_by")}
        return (f"limits   {len(record.get('joints', {}))} joints, narrowed: {narrowed or 'none'}; interaction force "
                f"{record.get('interaction_force_n')} N; keep-in {'yes' if record.get('keep_in') else 'no'}; "
                f"stop: {record.get('stop')}")
    if kind == "intervention":
        return f"event    {record.get('message')}"
    if kind == "end":
        return (f"end      passed {record.get('passed')}, safety events {record.get('safety_events')}, "
                f"{record.get('sim_time_s')} s simulated")
    return f"{kind}"


def cmd_audit(args: argparse.Namespace) -> int:
    path = Path(args.run_dir) / LOG
    if not path.exists():
        print(f"{args.run_dir}: no {LOG} (a run writes one with --out)", file=sys.stderr)
        return EXIT_INVALID
    log = check(path, audit_key())
    records = log.records
    for record in records:
        print(f"{record.get('seq', '?'):>3}  {_line(record)}")
    if log.torn is not None:
        print(f"torn     the last line is cut short ({log.torn!r}…): a write the process's end interrupted; "
              "left out")
    if records and not log.finished:
        last = records[-1]
        at = f" (t={last['t']:g} s)" if isinstance(last.get("t"), (int, float)) else ""
        print(f"unfinished  the log ends without its closing record: the run did not finish (killed, or the machine "
              f"stopped); checked up to its last record, {last.get('seq', '?')} ({last.get('kind')}{at})")
    if log.problems:
        for problem in log.problems:
            print(f"TAMPERED: {problem}", file=sys.stderr)
        return EXIT_FAILED
    keyed = f", keyed ({KEY_ENV})" if audit_key() is not None else ""
    print(f"chain intact: {len(records)} records{keyed}{'' if log.finished else ' (up to where it ends)'}; "
          f"last hash {records[-1]['hash']}")
    return EXIT_OK


def add_parser(sub) -> None:
    a = sub.add_parser("audit", help="check a run's safety log (hash chain) and print it")
    a.add_argument("run_dir", help="the run's folder (rehabkit run --out DIR)")
    a.set_defaults(func=cmd_audit)


RECORDING, BAG = "run.rrd", "run.mcap"
LEFT = {"recording": f"{RECORDING}.tmp", "bag": f".{BAG}.part"}


def killed_leftovers(out: Path) -> list[str]:
    """What a killed run left in ``out`` and nobody recovered (empty: none)."""
    if not out.is_dir() or (out / "summary.json").exists() and not any((out / n).exists() for n in LEFT.values()):
        return []
    left = [name for name in LEFT.values() if (out / name).exists()]
    if (out / LOG).exists() and not (out / "summary.json").exists():
        from rehabkit.core.log.safety_log import check

        if not check(out / LOG).finished:
            left.append(LOG)
    return left


def _recording(path: Path) -> dict[str, dict[str, tuple[np.ndarray, np.ndarray]]]:
    """Each joint's series in the recording: joint → {'measured_deg': (t, values), 'reference_deg': …}."""
    import warnings

    from rerun.chunk import RrdReader

    series: dict[str, dict[str, list]] = {}
    with warnings.catch_warnings():  # (a file cut short has no footer: read whole, as the SDK then says it does)
        warnings.filterwarnings("ignore", "RRD file has no footer")
        chunks = RrdReader(str(path)).stream().to_chunks()
    for chunk in chunks:
        parts = str(chunk.entity_path).strip("/").split("/")
        if len(parts) != 3 or parts[0] != "joints" or "sim_time" not in chunk.timeline_names:
            continue
        batch = chunk.to_record_batch()
        column = next((f.name for f in batch.schema if f.name.endswith(":scalars")), None)
        if column is None:
            continue
        t = batch.column("sim_time").cast("int64").to_numpy() / 1e9
        values = np.array([v[0] if v else np.nan for v in batch.column(column).to_pylist()], float)
        series.setdefault(parts[1], {}).setdefault(parts[2], []).append((t, values))
    out: dict[str, dict[str, tuple[np.ndarray, np.ndarray]]] = {}
    for joint, kinds in series.items():
        for kind, pieces in kinds.items():
            t = np.concatenate([p[0] for p in pieces])
            v = np.concatenate([p[1] for p in pieces])
            order = np.argsort(t, kind="stable")
            out.setdefault(joint, {})[kind] = (t[order], v[order])
    return out


def _metrics(series: dict) -> tuple[dict[str, float], dict[str, Any]]:
    metrics: dict[str, float] = {}
    per_joint: dict[str, Any] = {}
    ends = [s[0][-1] for kinds in series.values() for s in kinds.values() if len(s[0])]
    metrics["sim_time_s"] = float(max(ends)) if ends else 0.0
    worst_rms, worst_max, unit = 0.0, 0.0, None
    for joint, kinds in series.items():
        measured = next((k for k in kinds if k.startswith("measured_")), None)
        if measured is None:
            continue
        u = measured.split("_", 1)[1]  # (deg, or m for a prismatic joint)
        t, q = kinds[measured]
        metrics[f"rom_{u}_{joint}"] = float(np.nanmax(q) - np.nanmin(q)) if len(q) else 0.0
        reference = kinds.get(f"reference_{u}")
        if reference is not None and len(reference[0]) == len(t) and np.array_equal(reference[0], t):
            err = q - reference[1]
            rms, peak = float(np.sqrt(np.nanmean(err**2))), float(np.nanmax(np.abs(err)))
            per_joint[joint] = {f"tracking_rms_{u}": rms, f"tracking_max_{u}": peak}
            if u == "deg":
                worst_rms, worst_max, unit = max(worst_rms, rms), max(worst_max, peak), u
    if unit is not None:
        metrics["tracking_rms_deg"], metrics["tracking_max_deg"] = worst_rms, worst_max
    return metrics, per_joint


def _rebuild_bag(part: Path, whole: Path) -> dict[str, Any]:
    """The messages of a bag cut short, written again as a whole MCAP file (temp, then rename)."""
    import struct

    from mcap.exceptions import McapError
    from mcap.records import Channel, Message, Schema
    from mcap.stream_reader import StreamReader
    from mcap.writer import CompressionType, Writer

    tmp = whole.with_name(whole.name + ".tmp")
    schemas: dict[int, int] = {}
    channels: dict[int, int] = {}
    counts: dict[str, int] = {}
    types: dict[str, str] = {}
    first = last = None
    with open(part, "rb") as src, open(tmp, "wb") as dst:
        writer = Writer(dst, compression=CompressionType.ZSTD)
        writer.start(profile="ros2", library="rehabkit recover")
        topics: dict[int, str] = {}
        names: dict[int, str] = {}  # schema id → its type's name
        try:
            for record in StreamReader(src, skip_magic=False).records:
                if isinstance(record, Schema) and record.id not in schemas:
                    schemas[record.id] = writer.register_schema(record.name, record.encoding, record.data)
                    names[record.id] = record.name
                elif isinstance(record, Channel) and record.id not in channels:
                    channels[record.id] = writer.register_channel(record.topic, record.message_encoding,
                                                                  schemas.get(record.schema_id, 0), record.metadata)
                    topics[record.id] = record.topic
                    types[record.topic] = names.get(record.schema_id, "")
                elif isinstance(record, Message) and record.channel_id in channels:
                    writer.add_message(channels[record.channel_id], record.log_time, record.data,
                                       record.publish_time, record.sequence)
                    counts[topics[record.channel_id]] = counts.get(topics[record.channel_id], 0) + 1
                    first = record.log_time if first is None else min(first, record.log_time)
                    last = record.log_time if last is None else max(last, record.log_time)
        except (McapError, EOFError, ValueError, struct.error):  # (the cut: a record written halfway)
            pass
        writer.finish()
        dst.flush()
        os.fsync(dst.fileno())
    os.replace(tmp, whole)
    part.unlink()
    return {"messages": counts, "types": types, "until_s": (last - first) / 1e9 if first is not None else 0.0}


RRD_MAGIC, RRD_HEADER, RRD_FRAME = b"RRF2", 12, struct.Struct("<QQ")  # (Rerun's file header; a message's kind, length)


def _whole_messages(path: Path) -> int:
    """Cut a killed run's recording after its last whole message (Rerun's file: a 12-byte header, then messages of a
    16-byte header — kind, length — and that many bytes): a kill during a write leaves the last one torn, which Rerun's
    reader refuses whole ("payload exceeds file size"). Returns how many bytes were cut off (0: none)."""
    size = path.stat().st_size
    with open(path, "r+b") as f:
        if f.read(4) != RRD_MAGIC:
            return 0
        at = RRD_HEADER
        while at + RRD_FRAME.size <= size:
            f.seek(at)
            kind, length = RRD_FRAME.unpack(f.read(RRD_FRAME.size))
            if kind == 0:  # (the end message: a footer may follow it)
                return 0
            if at + RRD_FRAME.size + length > size:
                break
            at += RRD_FRAME.size + length
        if at == size:
            return 0
        f.truncate(at)
        os.fsync(f.fileno())
        return size - at


def _indexed(path: Path) -> bool:
    """The recording given the footer a killed run's file lacks (Rerun's manifest of its chunks: ``rerun rrd
    verify`` refuses a file without one), by Rerun's own ``rrd migrate`` (which keeps a backup: removed once the
    migrated file is in place, put back if it failed)."""
    import subprocess

    backup = path.with_name(f"{path.stem}.backup{path.suffix}")
    # (rerun_cli, shipped with the SDK, starts the same `rerun` binary as `python -m rerun` without importing the
    # SDK first: ~0.5 s of CPU and a second of a recovery's wall time less)
    done = subprocess.run([sys.executable, "-m", "rerun_cli", "rrd", "migrate", str(path)], capture_output=True,
                          text=True, timeout=300)
    if done.returncode == 0 and path.exists():
        backup.unlink(missing_ok=True)
        return True
    if backup.exists():
        os.replace(backup, path)
    return False


def _plugins(logged: dict[str, str], ran: dict) -> dict[str, Any]:
    """The plugins as a finished run's summary lists them (kind → type, package, version; sensors by name), from the
    safety log's ``kind:type → "package version"`` and the scenario as it ran (the sensors' names)."""
    out: dict[str, Any] = {}
    sensors = ran.get("sensors") if isinstance(ran, dict) else None
    for key, said in logged.items():
        kind, _, kind_type = key.partition(":")
        package, _, version = str(said).partition(" ")
        entry = {"type": kind_type, "package": package, "version": version}
        if kind != "sensor":
            out[kind] = entry
        elif isinstance(sensors, dict):
            for name, spec in sensors.items():
                if isinstance(spec, dict) and spec.get("type") == kind_type:
                    out.setdefault("sensors", {})[name] = {**entry, "entry_point": kind_type}
    return out


def recover(out: Path) -> dict[str, Any]:
    """Make ``out`` (a killed run's folder) a run folder; returns its summary (also written to ``summary.json``)."""
    from rehabkit.core.io import atomic_write_json
    from rehabkit.core.log.safety_log import check

    log = check(out / LOG) if (out / LOG).exists() else None
    run = next((r for r in log.records if r.get("kind") == "run"), {}) if log is not None else {}
    said: list[str] = []
    metrics: dict[str, float] = {}
    per_joint: dict[str, Any] = {}
    outputs: dict[str, str] = {}
    recovered: dict[str, Any] = {}
    if (out / LEFT["recording"]).exists():
        try:
            if torn := _whole_messages(out / LEFT["recording"]):
                recovered["recording_torn_bytes"] = torn
                said.append(f"the recording's last message was written halfway: its {torn} bytes left out")
            series = _recording(out / LEFT["recording"])
            metrics, per_joint = _metrics(series)
            os.replace(out / LEFT["recording"], out / RECORDING)
            outputs["rrd"] = RECORDING
            recovered["recording_until_s"] = metrics["sim_time_s"]
            if not _indexed(out / RECORDING):
                said.append("the recording's footer (its index) could not be written: Rerun reads it whole, "
                            "`rerun rrd verify` does not pass it")
        except Exception as exc:  # noqa: BLE001 (said in the summary: the file is left as it was)
            said.append(f"the recording could not be read ({type(exc).__name__}: {exc}); left as {LEFT['recording']}")
    if (out / LEFT["bag"]).exists():
        bag = _rebuild_bag(out / LEFT["bag"], out / BAG)
        recovered["bag_until_s"], recovered["bag_messages"] = bag["until_s"], bag["messages"]
    events = [r for r in (log.records if log is not None else []) if r.get("kind") == "intervention"
              and r.get("level") == "ERROR"]
    if log is not None:
        outputs["safety_log"] = LOG
        recovered["safety_log_records"] = len(log.records)
        if log.torn:
            said.append("the safety log's last line was written halfway: left out")
    said.append("not computed again: the task's outcome measures and the expectations' verdicts (the plans, the "
                "targets and the person are not in the recording); `rehabkit replay` runs it again for them")
    metrics["safety_events"] = float(len(events))
    scenario = run.get("scenario", {}).get("file", "")
    name, ran = Path(scenario).stem if scenario else out.name, {}
    if (out / SNAPSHOT).exists():  # (the scenario as it ran, written as the session opened)
        outputs["scenario"] = SNAPSHOT
        import yaml

        with contextlib.suppress(yaml.YAMLError, AttributeError, TypeError):
            ran = yaml.safe_load((out / SNAPSHOT).read_text()) or {}
            name = ran.get("name") or name
    summary = {
        "scenario": scenario, "name": name,
        "ended": RunEnding("killed (recovered)", "the process was killed before it finished; this folder was made from "
                           "what it left by `rehabkit recover`").as_dict(),
        "passed": False, "metrics": metrics, "per_joint": per_joint, "expectations": [],
        "safety": {"tripped": bool(events), "events": events},
        "plugins": _plugins(run.get("plugins", {}), ran), "seed": run.get("seed"), "outputs": outputs,
        "recovered": {**recovered, "said": said},
    }
    if "bag_messages" in recovered:  # (as a finished run's summary lists its bag)
        summary["bag"] = {"file": BAG, "topics": {t: {"type": bag["types"].get(t, ""), "messages": n}
                                                  for t, n in sorted(bag["messages"].items())}}
    if log is not None and log.records:  # (the last hash: to keep elsewhere, as a finished run's)
        summary["safety_log_hash"] = log.records[-1]["hash"]
    atomic_write_json(out / "summary.json", summary)
    return summary


def cmd_recover(args: argparse.Namespace) -> int:
    out = Path(args.run_dir)
    if not out.is_dir():
        print(f"error: {out}: no such folder (give the folder the killed run wrote, its --out)", file=sys.stderr)
        return EXIT_INVALID
    left = killed_leftovers(out)
    if not left:
        print(f"error: {out} holds no killed run to recover (it needs {LEFT['recording']}, {LEFT['bag']} or a "
              f"{LOG} without its closing record, and no summary.json)", file=sys.stderr)
        return EXIT_INVALID
    summary = recover(out)
    rec = summary["recovered"]
    kept = []
    if "recording_until_s" in rec:
        kept.append(f"the recording up to {rec['recording_until_s']:.3f} s")
    if "bag_until_s" in rec:
        kept.append(f"the bag up to {rec['bag_until_s']:.3f} s ({sum(rec['bag_messages'].values())} messages)")
    if "safety_log_records" in rec:
        kept.append(f"the safety log's {rec['safety_log_records']} records")
    print(f"recovered {out}: " + ", ".join(kept))
    for line in rec["said"]:
        print(f"  {line}")
    print(f"wrote {out / 'summary.json'} (ended: killed (recovered))")
    return EXIT_OK


def add_recover_parser(sub) -> None:
    rp = sub.add_parser("recover", help="make a killed run's folder a run folder: the recording and the bag whole, "
                                        "a summary from what the recording holds")
    rp.add_argument("run_dir", metavar="DIR")
    rp.set_defaults(func=cmd_recover)
