"""Shared fixtures: built-in robots and a registry with extra in-process plugins."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"
# hit_roundtrip.yaml's first round trip only, A → B → A in 4.5 s: for runs paced in real time (a worker asleep)
FIRST_ROUND_TRIP = {"duration": 4.5, "planner.segment_durations": [2.0, 2.0],
                    "task.targets": [{"name": "A", "joints_deg": [0, 90, 90, 30, -90, 90]},
                                     {"name": "B", "position": [-0.45, -0.1, -0.3], "orientation_of": "A"},
                                     {"name": "C", "same_as": "A"}]}
DATA = Path(__file__).resolve().parent / "data"
# hypothesis keeps a cache of the constants in the code it tests; in a folder of its own, not the work tree (the suite
# leaves that as it found it)
os.environ.setdefault("HYPOTHESIS_STORAGE_DIRECTORY", os.path.join(tempfile.gettempdir(), "rehabkit-tests-hypothesis"))
if os.environ.get("PYTEST_XDIST_WORKER"):
    # every core has a worker: a lock-step link's ends wait asleep (polling would take the core the other end needs
    # to answer); bridges the tests start inherit it
    os.environ.setdefault("REHABKIT_LINK_POLL_S", "0")
pytest_plugins = ["pytester"]  # (the README's scenario-test example runs in a pytest of its own, in-process)
collect_ignore = ["bad_scenarios"]  # refused on purpose (tests/test_bad_corpus.py), not scenario tests


def registry_with(kind: str, name: str, config, factory, package: str = "tests", version: str = "0", **add):
    """The installed plugins and one more of ``kind``, registered in-process through its hook as an installed
    package's would be (``registry.add(name, config=, factory=, **add)``), provided by ``package`` ``version``."""
    import types

    from rehabkit import hookimpl
    from rehabkit.core.plugins.registry import Provider, load_plugins

    def register(registry):
        registry.add(name, config=config, factory=factory, **add)

    hook = f"rehabkit_register_{kind}s"
    register.__name__ = hook
    plugin = types.SimpleNamespace(**{hook: hookimpl(register)})
    return load_plugins(extra=[(plugin, Provider(package, version, name))])


@pytest.fixture(scope="session")
def hit():
    from rehabkit_plugins.robots.hit import HitConfig, HitRobot

    return HitRobot(HitConfig())


@pytest.fixture(scope="session")
def lexos():
    from rehabkit_plugins.robots.lexos import LexosConfig, LexosRobot

    return LexosRobot(LexosConfig())


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture(scope="session", autouse=True)
def _suite_state(tmp_path_factory):
    """Runs made by module- and session-scoped fixtures keep their e-stop latches out of the user's state too (a
    latch someone set by hand would refuse them)."""
    before = os.environ.get("REHABKIT_STATE")
    os.environ["REHABKIT_STATE"] = str(tmp_path_factory.mktemp("suite-state"))
    yield
    if before is None:
        os.environ.pop("REHABKIT_STATE", None)
    else:
        os.environ["REHABKIT_STATE"] = before


@pytest.fixture(autouse=True)
def _own_state(tmp_path, monkeypatch):
    """Each test keeps its e-stop latches to itself (rehabkit.core.safety.estop: $REHABKIT_STATE)."""
    monkeypatch.setenv("REHABKIT_STATE", str(tmp_path / "state"))


def checked(layer, t: float, q, qd, tau) -> np.ndarray:
    """The torque the safety ``layer`` sends for state ``q``, ``qd`` and command ``tau`` at ``t`` (its check of the
    packed row the loop hands it)."""
    return layer.check_row(t, np.concatenate((q, qd, tau)))


# the suite's longest units of work first: pytest-xdist hands the units (an xdist_group, else a test) to its workers
# in collection order, and a long one handed out last keeps the other worker idle to the end. In order: the paced
# real-time tests (one after the other, mostly asleep), the Ray sweeps, the safety report (27 runs), then the
# scenarios whose shared run several tests read
LONGEST_FIRST = ("realtime", "ray", "tests/test_safety_report.py", "scenario:coman_juggling",
                 "scenario:lexos_reaching", "scenario:lexos_patient", "scenario:lexos_myoarm")


def pytest_configure(config: pytest.Config) -> None:
    # the suite starts ~75 Pythons that import rehabkit (its CLI, bridges, drives, frame servers): an installed
    # package's bytecode was compiled when pip installed it, an editable checkout's is written at its first import,
    # but not where PYTHONDONTWRITEBYTECODE is set (as on CI's machines), where each process compiled the ~110 modules
    # it imports again (~0.15-0.2 CPU-s each, ~12 in all). Compiled once here, by the controller, before any worker
    # or process starts (~0.5 s on a fresh clone; the __pycache__ folders are git-ignored, as any default Python
    # leaves them)
    if not hasattr(config, "workerinput"):
        import compileall

        for package in ("rehabkit", "plugins"):
            compileall.compile_dir(ROOT / package, quiet=1)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    def rank(item: pytest.Item) -> int:
        unit = next((m.args[0] for m in item.iter_markers("xdist_group") if m.args), item.nodeid)
        return next((i for i, name in enumerate(LONGEST_FIRST) if unit.startswith(name)), len(LONGEST_FIRST))

    items.sort(key=rank)  # (stable: the rest in the order they were collected)
