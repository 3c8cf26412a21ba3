"""The wording of each kind of message, asserted once, in full, for one constructed value (issue 47).

Elsewhere tests assert an error's fields (a diagnostic's path, line and column, a breach's joint and quantity, an
event's rule, an exit code); here the rendered text of one of each, so the wording is checked in one place and a
change of words is one edit here, not a hunt through the suite."""

import numpy as np
import pytest

from rehabkit.core.run.session import PlanRefusal
from rehabkit.core.safety.event import Clipping, SafetyEvent
from rehabkit.core.safety.limit_breach import LimitBreach
from rehabkit.core.scenario.errors import Diagnostic, Mark, ScenarioError
from rehabkit.core.setup.errors import PluginSetupError, SetupError
from tests.conftest import DATA


def test_a_located_scenario_error_reads_file_line_col_path_message():
    d = Diagnostic(Mark("arm3.yaml", 18, 3), "robot.joints.2.range_deg", "lower bound 90.0 is above upper 80.0")
    assert str(d) == "arm3.yaml:18:3: robot.joints.2.range_deg: lower bound 90.0 is above upper 80.0"
    assert str(Diagnostic(Mark("arm3.yaml", 0, 0), "", "empty file")) == "arm3.yaml: empty file"  # (no place)
    both = ScenarioError([d, Diagnostic(Mark("arm3.yaml", 25, 11), "duration", "a number is needed here")])
    assert str(both) == ("arm3.yaml:18:3: robot.joints.2.range_deg: lower bound 90.0 is above upper 80.0\n"
                         "arm3.yaml:25:11: duration: a number is needed here")


def test_a_diagnostics_fix_is_said_after_its_message():
    """The fix is a field of its own (tests elsewhere assert ``.fix``); said after the message, past a ``;``."""
    d = Diagnostic(Mark("arm3.yaml", 9, 5), "planner.type", "unknown planner plugin 'multicubic'",
                   "did you mean 'multi-cubic'?")
    assert str(d) == "arm3.yaml:9:5: planner.type: unknown planner plugin 'multicubic'; did you mean 'multi-cubic'?"
    assert d.text == "unknown planner plugin 'multicubic'; did you mean 'multi-cubic'?"


def test_a_refusal_with_its_fix_reads_as_one_line_from_validate():
    """The command line's one located line per problem, its fix after it (the example of examples/)."""
    from tests.test_cli import cli

    r = cli("validate", "examples/patient_out_of_range.yaml")
    assert r.stderr == ("scenarios/hit_roundtrip.yaml:30:7: task.targets.0: target 'A': its joint values put elbow_1 "
                        "beyond its position limit (90.0°, limit 80.0°): patient P03's passive range is [20.0, 80.0]°; "
                        "move the target into the range, or set patient.outside_rom: nearest to use the nearest "
                        "admissible point\n")


def test_a_plugins_setting_or_planning_or_setup_error_says_its_fix_after_its_problem():
    from rehabkit.core.kinds.errors import PlanningError, SettingError, apart

    assert str(SettingError("bandwidth_hz", "100 is too high for a control period of 1 ms", fix="at most 48")) == \
        "bandwidth_hz: 100 is too high for a control period of 1 ms; at most 48"
    planning = PlanningError("target 'B': 37% of the way along the straight line 'hand' comes within 3 mm of "
                             "'tray' (clearance_m 0.02)", target="B", fix="add a via point")
    assert str(planning) == ("target 'B': 37% of the way along the straight line 'hand' comes within 3 mm of 'tray' "
                             "(clearance_m 0.02); add a via point")
    assert apart(planning) == ("target 'B': 37% of the way along the straight line 'hand' comes within 3 mm of 'tray' "
                               "(clearance_m 0.02)", "add a via point")  # (how a refusal passes the fix on)
    assert str(SetupError("task.start: target 'A' is Cartesian and the robot's IK gives no configuration for it "
                          "within the joint ranges", fix="start from a joint-space target")) == (
        "task.start: target 'A' is Cartesian and the robot's IK gives no configuration for it within the joint "
        "ranges; start from a joint-space target")


def test_a_plugins_refusal_names_the_plugin_then_its_reason(tmp_path):
    from rehabkit.core.run.runner import Runner
    from rehabkit.core.scenario.loader import load_scenario

    path = tmp_path / "arm3.yaml"
    path.write_text((DATA / "arm3_dh.yaml").read_text().replace("kp: [300, 300, 150]", "kp: [300, 300]"))
    with pytest.raises(PluginSetupError) as err:
        Runner(load_scenario(path)).build()
    assert str(err.value) == f"{path}:18:3: controller.kp: controller 'joint-pd': has 2 values; the robot has 3 joints"


def test_a_limit_breach_describes_itself_in_the_joints_own_unit():
    assert LimitBreach("position", "elbow", np.radians(131.2), np.radians(120.0), 0.25).describe() == \
        "elbow beyond its position limit at t+0.250s (131.2°, limit 120.0°)"
    assert LimitBreach("torque", "slide", 120.0, 100.0, None, False).describe() == \
        "slide beyond its force limit (120.0 N, limit 100.0 N)"  # a prismatic joint's torque is a force
    assert LimitBreach("velocity", "slide", 0.1234, 0.12, None, False).describe() == \
        "slide beyond its velocity limit (0.123 m/s, limit 0.120 m/s)"  # (metres to the millimetre)


def test_a_plan_refusal_says_the_breach_or_the_actions_the_backend_cannot_do():
    """A plan refusal's reason, as the run's plan gate words it (a refused plan's ``PlanRefusal.reason``)."""
    from types import SimpleNamespace

    from rehabkit.core.run.plan_gate import PlanGate

    breach = LimitBreach("velocity", "wrist_1", np.radians(12.0), np.radians(10.0), 0.5)
    gate = SimpleNamespace(space=SimpleNamespace(limit_breach=lambda plan, within: breach), duration=2.0,
                           scene_actions=("attach",))
    reason, found, actions = PlanGate.problem(gate, SimpleNamespace(actions=[]), 1.0)
    refusal = PlanRefusal(1.0, reason, breach=found, actions=actions)
    assert refusal.unplannable and refusal.breach is breach and refusal.reason == \
        "planned trajectory: wrist_1 beyond its velocity limit at t+0.500s (12.0 °/s, limit 10.0 °/s)"
    gate.space.limit_breach = lambda plan, within: None
    assert PlanGate.problem(gate, SimpleNamespace(actions=[(0.5, "weld", {})]), 1.0) == (
        "plan action(s) ['weld'] unknown; the backend can do: attach", None, ("weld",))


def test_a_safety_events_message_says_when_and_what():
    events: list[SafetyEvent] = []
    Clipping(["elbow", "wrist"], np.array([10.0, 5.0]), 0.002, events.append).step(
        0.25, np.array([12.0, 1.0]), np.array([True, False]))
    (e,) = events
    assert (e.rule, e.joint, e.value, e.limit, e.level) == ("torque-clip", "elbow", 12.0, 10.0, "WARN")
    assert e.message == "t=0.250s: commanded torque clipped to the effort limit"


def test_a_setup_error_is_its_message():
    breach = LimitBreach("position", "elbow", np.radians(131.2), np.radians(120.0))
    err = SetupError(f"the first plan would break a joint limit: {breach.describe()}", breach)
    assert err.breach is breach
    assert str(err) == ("the first plan would break a joint limit: "
                        "elbow beyond its position limit (131.2°, limit 120.0°)")


def test_a_cli_error_line_names_the_file_then_the_problem(capsys):
    from rehabkit.cli import main

    assert main(["validate", "/nonexistent/s.yaml"]) == 2
    assert capsys.readouterr().err == "/nonexistent/s.yaml: no such file\n"


def test_a_bag_error_is_said_at_the_bag_and_each_topics_role():
    from rehabkit.bags.bag_content import BagError

    err = BagError("s.mcap", "wrench", "no topic /wrench; the bag has /arm/joint_states (sensor_msgs/msg/JointState)",
                   more=[("targets", "no topic /targets")])
    assert str(err) == ("s.mcap: --topics wrench: no topic /wrench; the bag has /arm/joint_states "
                        "(sensor_msgs/msg/JointState)\ns.mcap: --topics targets: no topic /targets")


def test_a_key_file_error_names_the_file_its_problem_then_the_fix():
    from rehabkit.hardware.config import LinkKeyError
    from rehabkit.hardware.security.keys import KeyFileError

    assert str(KeyFileError("k.key", "readable by others (mode 644)", "chmod 600 k.key")) == \
        "key file k.key: readable by others (mode 644); chmod 600 k.key"
    assert str(LinkKeyError("udp://10.0.0.2:7000", None, "the bridge needs a key (it was started with --key)")) == \
        ("the bridge at udp://10.0.0.2:7000 refuses this host's session: the bridge needs a key (it was started with "
         "--key); set backend.key_file to the robot's key file (the one the bridge was given)")


def test_a_path_refused_at_an_end_says_where_that_end_lies():
    from rehabkit.geometry.box_avoid import NoPathError, plan_path
    from rehabkit.geometry.solids import Box

    with pytest.raises(NoPathError) as inside:
        plan_path([0, 0, 0], [1, 0, 0], [Box([0, 0, 0], [0.2, 0.2, 0.2], name="tray")], margin=0.0)
    assert str(inside.value) == "start [0.0, 0.0, 0.0] lies inside obstacle 'tray' (margin 0.0 m)"
    with pytest.raises(NoPathError) as below:
        plan_path([0, 0, -0.1], [1, 0, 0], [], floor=([0, 0, 1], 0.0))
    assert str(below.value) == "start [0.0, 0.0, -0.1] lies below the floor"


def test_a_stops_event_says_when_its_cause_then_the_stop(hit):
    from rehabkit.core.safety.layer import SafetyLayer
    from rehabkit.core.scenario.safety import SafetyConfig

    layer = SafetyLayer(hit.model, SafetyConfig(), gravity=hit.gravity_torque)
    layer.trip(1.0, (hit.model.limits.lower + hit.model.limits.upper) / 2, "plan", "a test's own stop")
    (e,) = layer.events
    assert (e.rule, e.data["category"]) == ("plan", 2)
    assert e.message == "t=1.000s: a test's own stop; controlled stop, then held (category 2)"


def test_a_misspelt_name_is_offered_the_nearest_ones_or_the_choices():
    from rehabkit.core.kinds.names import nearest, suggest

    said = [suggest("multicubic", ["multi-cubic", "min-jerk"]), suggest("elbow1", ["elbow_1", "elbow_2", "wrist_1"]),
            suggest("handel", ["base", "elbow_1_link"])]
    assert said == ["; did you mean 'multi-cubic'?", "; did you mean 'elbow_1' or 'elbow_2'?",
                    "; choices: base, elbow_1_link"]
    assert nearest("multicubic", ["multi-cubic", "min-jerk"]) == "did you mean 'multi-cubic'?"  # (a fix field's)


def test_a_key_in_the_other_kind_of_joints_unit_names_the_key_to_write_and_the_robots_own_limit():
    from rehabkit.core.setup.limits import WrongUnitKey

    said = [WrongUnitKey("finger", "range_deg", "range_m", False, "[0, 0.04] m").describe(),
            WrongUnitKey("elbow", "velocity_m_s", "velocity_deg_s", True, "124.6 deg/s").describe()]
    assert said == ["finger is a prismatic joint: range_deg [deg] is for a revolute joint; write range_m instead, in m "
                    "(the robot's own: [0, 0.04] m)",
                    "elbow is a revolute joint: velocity_m_s [m/s] is for a prismatic joint; write velocity_deg_s "
                    "instead, in deg/s (the robot's own: 124.6 deg/s)"]
    finger = WrongUnitKey("finger", "range_deg", "range_m", False, "[0, 0.04] m")  # (a diagnostic's two fields)
    assert (finger.problem, finger.fix) == ("finger is a prismatic joint: range_deg [deg] is for a revolute joint",
                                            "write range_m instead, in m (the robot's own: [0, 0.04] m)")


def test_a_broken_safety_log_chain_says_the_record_its_line_and_what_is_wrong():
    from rehabkit.core.log.safety_log import ChainBreak

    breaks = [ChainBreak(3, 2, "intervention", "edited"), ChainBreak(3, 2, "intervention", "edited", keyed=True),
              ChainBreak(3, 3, "end", "out-of-order"), ChainBreak(5, None, None, "unreadable"),
              ChainBreak(0, None, None, "empty")]
    assert [str(b) for b in breaks] == [
        "record 2 (intervention, line 3): its content does not match its hash (edited, or checked without the key it "
        "was written with)",
        "record 2 (intervention, line 3): its content does not match its hash (edited)",
        "record 3 (end, line 3): does not follow the record before it (one removed, inserted or reordered)",
        "line 5: not a record of this log",
        "the log holds no records"]


def test_a_latched_estop_says_since_when_why_and_the_command_that_clears_it(tmp_path):
    from rehabkit.core.safety.estop import EStopLatch

    latch = EStopLatch(tmp_path / "hit-1.json", "hit-1")
    latch.press("the test's own press", by="robot")
    since = latch.latched()["since"]
    assert latch.refusal("the robot") == (f"the e-stop of the robot is latched (since {since}, the test's own press): "
                                          "deal with its cause, then clear it with `rehabkit estop clear hit-1 --by "
                                          "NAME`")


def test_a_drive_in_fault_says_its_code_and_that_a_person_must_clear_the_latch():
    from rehabkit.canopen.config import DriveFaultError
    from rehabkit.canopen.drives.start_checks import check_no_fault

    class _Master:  # (a drive's object dictionary as the master reads it: its error code, 0x603F)
        states, ids = ["OPERATION_ENABLED", "FAULT"], [1, 2]
        remotes = [None, type("Remote", (), {"sdo": {0x603F: type("Entry", (), {"raw": 0x2310})()}})()]

    with pytest.raises(DriveFaultError) as err:
        check_no_fault(_Master(), ["shoulder_1", "shoulder_2"], cleared=False, latch_name="hit-1")
    assert str(err.value) == ("drive 2 (shoulder_2): is in FAULT (0x2310 continuous over-current): its fault is reset "
                              "only once a person has cleared the robot's e-stop latch (`rehabkit estop clear hit-1 "
                              "--by NAME`)")


def test_the_links_refusals_say_what_applies_at_this_bridge():
    """A bridge behind a latched e-stop names what clears it there (its clearing key, its keypad); a host refused for
    another's live session, or taken over, is told so (not to match keys)."""
    from pathlib import Path
    from types import SimpleNamespace

    from rehabkit.hardware.bridge_says import latched_message
    from rehabkit.hardware.config import LinkBusyError, SessionTakenOverError
    from rehabkit.hardware.link.protocol import CLEAR_AT_KEYPAD, CLEAR_BY_KEY, ESTOPPED

    def link(status):
        return SimpleNamespace(addr=("10.0.0.2", 7000), estop_name="hit-1", key=SimpleNamespace(path=Path("k.key")),
                               process=None, status=ESTOPPED | status)

    latched = "the e-stop of the robot behind the bridge at udp://10.0.0.2:7000 is latched: deal with its cause, " \
        "then clear it with "
    assert latched_message(link(0)) == latched + "`rehabkit estop clear hit-1 --by NAME --bridge 10.0.0.2:7000 --key " \
        "k.key` while it runs, or the bridge's keypad"
    assert latched_message(link(CLEAR_BY_KEY)) == latched + "`rehabkit estop clear hit-1 --by NAME --bridge " \
        "10.0.0.2:7000 --key CLEAR_KEY_FILE` while it runs (the bridge's clearing key, its --clear-key file: it " \
        "takes no clear under the robot's key), or the bridge's keypad"
    assert latched_message(link(CLEAR_AT_KEYPAD)) == latched + "the bridge's keypad at the robot (c): it takes no " \
        "clear over the link (--clear-with keypad)"
    assert str(LinkBusyError("udp://10.0.0.2:7000", "the bridge serves another host's live session")) == \
        "the bridge at udp://10.0.0.2:7000 refuses this host's session: the bridge serves another host's live session"
    assert str(SessionTakenOverError("udp://10.0.0.2:7000", "keypad")) == (
        "the session with the bridge at udp://10.0.0.2:7000 was taken over by another host (the person at the robot "
        "allowed it on the bridge's keypad (a)): the robot is that host's now, and this run stops")


def test_an_unreachable_target_says_where_it_is_and_how_near_the_hand_came():
    from types import SimpleNamespace

    from rehabkit.core.kinds.interfaces import Target
    from rehabkit.core.setup.targets import unreachable

    far = np.eye(4)
    far[:3, 3] = [1.5, 0.0, 0.3]
    assert unreachable(Target("B", pose=far, position_only=True), SimpleNamespace(ik_closest_m=0.998)) == (
        "target 'B' at [1.5, 0.0, 0.3] m is out of reach: no position solution within the joint limits; the closest "
        "the hand came is 998 mm away (base frame; check the robot's base and the target's units)")


def test_a_plugin_that_does_not_load_or_is_installed_twice_names_the_packages():
    """What its import raised and the package to fix or uninstall; the two packages of one name (tests elsewhere
    assert ``PluginLoadError.provider``/``failure`` and ``PluginConflictError.providers``)."""
    from rehabkit.core.plugins.registry import Entry, PluginConflictError, PluginLoadError, PluginRegistry, Provider

    def missing():
        raise ModuleNotFoundError("No module named 'xyz'", name="xyz")

    exo = PluginRegistry([Entry("robot", "exo", missing, Provider("rehabkit-exo-driver", "1.2.3", "exo"))])
    with pytest.raises(PluginLoadError) as broken:
        exo.get("robot", "exo")
    assert str(broken.value) == ("ModuleNotFoundError: No module named 'xyz' (package rehabkit-exo-driver 1.2.3; fix "
                                 "or uninstall it)")
    twice = PluginRegistry([Entry("planner", "multi-cubic", missing, Provider("rehabkit", "0.1.0", "planners")),
                            Entry("planner", "multi-cubic", missing, Provider("fancy-planners", "1.2.3", "fancy"))])
    with pytest.raises(PluginConflictError) as conflict:
        twice.get("planner", "multi-cubic")
    assert str(conflict.value) == ("planner 'multi-cubic' is registered twice: by rehabkit 0.1.0 (entry point "
                                   "'planners') and by fancy-planners 1.2.3 (entry point 'fancy'); uninstall one of "
                                   "them or rename its plugin")


def test_an_object_a_drive_cannot_map_says_where_its_file_says_so_and_the_abort():
    from rehabkit.canopen.bus.drive_dictionary import read_dictionary
    from rehabkit.canopen.bus.pdo_plan import PdoPlanError, plan_pdos

    dcf = DATA / "canopen_eds" / "elmo_Gold-Drive.dcf"
    line = dcf.read_text("latin-1").splitlines().index("[6072]") + 1
    with pytest.raises(PdoPlanError) as refused:
        plan_pdos(read_dictionary(dcf, 1), 1, [(0x6040, 0, 16), (0x6072, 0, 16)], [])
    assert str(refused.value) == (f"0x6072 cannot be mapped into a PDO (PDOMapping=0 at elmo_Gold-Drive.dcf:{line}; "
                                  "CiA 301 abort 0x06040041)")
