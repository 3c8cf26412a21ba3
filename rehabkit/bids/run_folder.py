"""A finished run's folder, read for a dataset: ``summary.json`` (metrics, outcome measures, safety events, how it
ended), ``scenario.yaml`` (the scenario as it ran, its patient profile inlined), ``run.mcap`` (the ROS 2 bag: the
joints at the control rate) and the robot it ran, built again from that scenario for its joint names and kinematics.

What is missing or wrong is an :class:`ExportError`: the file and field, what is wrong, and the fix.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import yaml

from rehabkit.bids.bag_arrays import BagArrays, read_bag

BAG, SUMMARY, SCENARIO, SAFETY_LOG = "run.mcap", "summary.json", "scenario.yaml", "safety_log.jsonl"


class ExportError(ValueError):
    """Input a dataset can't be made from: ``where`` (a file, a field), what is wrong and the fix."""

    def __init__(self, where: Path | str, what: str, fix: str):
        super().__init__(f"{where}: {what}; {fix}")
        self.where, self.what, self.fix = str(where), what, fix


def label(text: str) -> str:
    """A BIDS label: the letters and digits of ``text`` (``hit-roundtrip`` → ``hitroundtrip``)."""
    return re.sub(r"[^A-Za-z0-9]", "", str(text))


@dataclass
class RunFolder:
    """One finished run, as read: its ``summary`` and ``scenario`` (dicts), the patient ``profile`` (the scenario's
    ``patient:``, or None), the bag's arrays, when it began (``start_ns``, Unix epoch) and the robot it ran."""

    path: Path
    summary: dict[str, Any]
    scenario: dict[str, Any]
    profile: dict[str, Any] | None
    bag: BagArrays
    start_ns: int
    robot: Any

    @property
    def name(self) -> str:
        return str(self.scenario.get("name") or self.summary.get("name") or self.path.name)

    @property
    def backend(self) -> str:
        return str(self.summary.get("plugins", {}).get("backend", {}).get("type", "mujoco"))

    @property
    def simulated(self) -> bool:
        """A session in simulation (MuJoCo: the robot and the person models) rather than with a robot (over the link,
        on CANopen drives): its dataset is marked simulated."""
        return self.backend == "mujoco"

    @property
    def started(self) -> datetime:
        return datetime.fromtimestamp(self.start_ns / 1e9, UTC)

    @property
    def run_id(self) -> str:
        return run_id(self.summary, self.path)


def run_id(summary: dict, folder: Path) -> str:
    """What tells a run from any other (its safety log's hash chain ends in it; else its summary's digest): kept in
    the dataset, so that a run exported again is recognised and not added twice."""
    import hashlib

    return str(summary.get("safety_log_hash") or hashlib.sha256((folder / SUMMARY).read_bytes()).hexdigest())[:16]


def _read_json(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ExportError(path, f"not JSON ({exc.msg} at line {exc.lineno})",
                          "it is written whole or not at all by a run: use the run's own folder") from exc


def _start_ns(folder: Path, bag: BagArrays) -> int:
    """When the run began: the bag's start (its ``/robot_description``), else the safety log's first record."""
    if bag.start_ns is not None:
        return int(bag.start_ns)
    log = folder / SAFETY_LOG
    if log.exists():
        first = json.loads(log.read_text().splitlines()[0])
        return int(datetime.strptime(first["time"], "%Y-%m-%dT%H:%M:%S%z").timestamp() * 1e9)
    return int(min(s.stamps[0] for s in bag.streams.values()))


_ROBOTS: dict[str, Any] = {}  # the robots built, by their scenario's robot and the person's segments (a sweep's runs)


def _robot(folder: Path, scenario: dict) -> Any:
    """The run's robot, built again from its scenario as the run built it (segments adapted to the person)."""
    from rehabkit.core.plugins.lifecycle import default_extensions
    from rehabkit.core.plugins.registry import default_registry
    from rehabkit.core.scenario.errors import ScenarioError
    from rehabkit.core.scenario.loader import load_scenario
    from rehabkit.core.setup.errors import SetupError

    key = json.dumps([scenario.get("robot"), (scenario.get("patient") or {}).get("segments"), str(folder)
                      if "file" in json.dumps(scenario.get("robot")) else ""], sort_keys=True, default=str)
    if key not in _ROBOTS:
        try:
            from rehabkit.core.setup.assembly import assemble

            # (its files where the run found them: relative to the scenario the run was given, as replay reads it)
            ran = json.loads((folder / SUMMARY).read_text()).get("scenario") if (folder / SUMMARY).exists() else None
            loaded = load_scenario(folder / SCENARIO, origin=Path(ran) if ran else None)
            _ROBOTS[key] = assemble(loaded, default_registry(), default_extensions(), upto="targets").robot
        except (ScenarioError, SetupError, ValueError) as exc:
            raise ExportError(folder / SCENARIO, f"the run's robot can't be built again ({exc})",
                              "export where the run's robot files are, as the run found them, with the plugins it "
                              "used installed") from exc
    return _ROBOTS[key]


def peek_run(folder: Path | str) -> tuple[dict, dict]:
    """A run folder's summary and scenario, its files checked (the bag's there, not read). Raises
    :class:`ExportError` where it is not a finished run with its bag."""
    folder = Path(folder)
    if not folder.is_dir():
        raise ExportError(folder, "no such run folder", "give the folder `rehabkit run --out DIR` wrote")
    if not (folder / SUMMARY).exists():
        fix = ("a killed run: `rehabkit recover " + str(folder) + "` makes it a run folder first"
               if (folder / "run.rrd.tmp").exists() or (folder / f".{BAG}.part").exists()
               else "give the folder `rehabkit run --out DIR` wrote")
        raise ExportError(folder / SUMMARY, "missing: not a finished run", fix)
    summary = _read_json(folder / SUMMARY)
    if not (folder / SCENARIO).exists():
        raise ExportError(folder / SCENARIO, "missing: the scenario as the run ran it", "give a run folder as "
                          "`rehabkit run` writes it (it keeps scenario.yaml)")
    scenario = yaml.safe_load((folder / SCENARIO).read_text()) or {}
    if not (folder / BAG).exists():
        raise ExportError(folder / BAG, "missing: the joints at the control rate are in the run's ROS 2 bag",
                          "run with --bag (`rehabkit replay " + str(folder) + " --bag` makes a simulated session "
                          "again, same seed and inputs)")
    return summary, scenario


def read_run(folder: Path | str) -> RunFolder:
    """The run in ``folder``, its bag read and its robot built. Raises :class:`ExportError` where it is not a
    finished run with its bag."""
    folder = Path(folder)
    summary, scenario = peek_run(folder)
    try:
        bag = read_bag(folder / BAG)
    except ValueError as exc:
        raise ExportError(folder / BAG, f"can't be read ({exc})", "give the bag the run wrote") from exc
    if "/joint_states" not in bag.streams or not len(bag.streams["/joint_states"].stamps):
        raise ExportError(folder / BAG, "no /joint_states messages", "give the bag the run wrote (`--bag`)")
    profile = scenario.get("patient") if isinstance(scenario.get("patient"), dict) else None
    return RunFolder(folder, summary, scenario, profile, bag, _start_ns(folder, bag), _robot(folder, scenario))
