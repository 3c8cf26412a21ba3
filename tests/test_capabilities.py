"""Declared capabilities: what plugins require of the robot and the backend is refused by name, by `validate`
before anything is built, and by the run's setup."""

from __future__ import annotations

import numpy as np
import pytest
from rehabkit_plugins.robots.contracts import ClusterPoints

from rehabkit.cli import main
from rehabkit.core.kinds.capabilities import (
    Cameras,
    Contacts,
    ExternalTorques,
    FloatingBase,
    Instruments,
    WorkspaceTable,
    missing_capabilities,
)
from rehabkit.core.plugins.types import Declared
from rehabkit.core.run.runner import Runner
from rehabkit.core.scenario.loader import load_scenario
from rehabkit.core.setup.errors import SetupError
from tests.conftest import SCENARIOS, registry_with
from tests.located import located

HIT = SCENARIOS / "hit_roundtrip.yaml"


def test_validate_refuses_a_controller_the_robot_cannot_serve(capsys):
    code = main(["validate", str(HIT), "--set", "controller={type: qp-stack, levels: [{tasks: [{type: com}]}]}"])
    assert (code, [x[1:] for x in located(capsys.readouterr().err)]) == (2, [(20, 3, "controller.type")])


def test_validate_refuses_a_sensor_the_backend_cannot_serve(capsys, tmp_path):
    # a hardware link reports no floating base's state: refused before a bridge is started
    code = main(["validate", str(SCENARIOS / "coman_juggling.yaml"), "--set", "backend.type=hardware"])
    assert (code, [x[1:] for x in located(capsys.readouterr().err)]) == (2, [(55, 5, "sensors.balance.type")])
    # instruments it reads, simulated or carried over the link from the robot side (accelerometers, force sensors)
    assert main(["validate", str(HIT), "--set", "backend.type=hardware", "--set",
                 "sensors.imu={type: accelerometer-array, body: elbow_2_link}"]) == 0


def test_several_missing_capabilities_are_named_together():
    sc = load_scenario(HIT, {"planner": {"type": "voxel-astar"}, "controller": {"type": "clik-pd"},
                             "sensors": {"b": {"type": "balance", "support_frames": ["a", "b", "c"]}}})
    with pytest.raises(SetupError) as err:
        Runner(sc).build()
    assert err.value.missing == {("planner", "voxel-astar"): (WorkspaceTable,), ("sensor", "balance"): (FloatingBase,)}


def test_the_built_in_robots_and_backends_declare_what_they_have(hit, lexos):
    from rehabkit_plugins.robots.capaman import CapamanConfig, CapamanRobot

    from rehabkit.sim.mujoco import MujocoBackend

    assert isinstance(lexos, WorkspaceTable) and not isinstance(hit, WorkspaceTable)
    assert isinstance(CapamanRobot(CapamanConfig()), ClusterPoints) and not isinstance(hit, FloatingBase)
    for cap in (Contacts, Cameras, Instruments, ExternalTorques):
        assert issubclass(MujocoBackend, cap)


def test_a_third_party_robot_states_a_capability_by_deriving_from_it(hit):
    class Planner:
        requires = (WorkspaceTable,)

    class TableArm(type(hit), WorkspaceTable):
        def workspace(self, resolution=0.01, progress=True, use_cache=True):
            return np.zeros((2, 2, 2))

    arm = TableArm.__new__(TableArm)
    requires = Declared.of(Planner).requires  # (what the registry reads of a plugin class when it registers)
    assert requires == (WorkspaceTable,)
    assert missing_capabilities(requires, arm) == []
    assert missing_capabilities(requires, hit) == ["a robot that has a workspace look-up table (robot.workspace)"]


def test_a_factory_function_declares_what_its_plugin_needs_when_it_registers(hit):
    """A plugin built by a function (no class attributes to read) gives its declarations to registry.add."""
    from rehabkit.plugin import Declared, Metric, StrictModel

    class Settings(StrictModel):
        pass

    def make_planner(config, context):  # a factory function
        raise AssertionError("not built in this test")

    registry = registry_with("planner", "table-walk", Settings, make_planner,
                             declared=Declared(requires=(WorkspaceTable,), metrics=(Metric("walked_m", "m"),)))
    info = registry.get("planner", "table-walk")
    assert [m.name for m in info.declared.metrics] == ["walked_m"]
    assert missing_capabilities(info.declared.requires, hit) == [
        "a robot that has a workspace look-up table (robot.workspace)"]
