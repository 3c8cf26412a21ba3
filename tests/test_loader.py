"""The YAML DSL: positions of errors, suggestions, extends, overrides."""

import textwrap
from pathlib import Path

import pytest

from rehabkit.core.scenario.errors import ScenarioError
from rehabkit.core.scenario.loader import deep_merge, load_scenario
from tests.conftest import SCENARIOS
from tests.located import where

HIT = SCENARIOS / "hit_roundtrip.yaml"


def write(tmp_path: Path, text: str, name: str = "s.yaml") -> Path:
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


def errors(path, overrides=()):
    with pytest.raises(ScenarioError) as exc:
        load_scenario(path, overrides)
    return [str(d) for d in exc.value.diagnostics]


def test_builtin_scenario_loads():
    sc = load_scenario(HIT).model
    assert sc.robot.type == "hit" and sc.planner.segment_durations == [2.0] * 4
    assert sc.backend.type == "mujoco" and sc.task.order() == ["A", "B", "C", "D", "E"]


def test_misspelt_plugin_and_field_are_located_with_suggestions(tmp_path):
    p = write(tmp_path, f"""\
        extends: {HIT}
        planner:
          type: multicubic
          segment_durations: [2, 2, 2, 2]
        controller:
          type: joint-pd
          kp: 10
          feedfoward: gravity
        """)
    with pytest.raises(ScenarioError) as err:
        load_scenario(p)
    assert [(*at, d.fix) for at, d in zip(where(err.value), err.value.diagnostics, strict=True)] == [
        (3, 9, "planner.type", "did you mean 'multi-cubic'?"),
        (8, 3, "controller.feedfoward", "did you mean 'feedforward'?")]  # (worded: tests/test_message_wording.py)


def test_value_errors_point_at_the_value_and_show_it(tmp_path):
    p = write(tmp_path, f"""\
        extends: {HIT}
        duration: five
        task:
          targets:
            - {{name: A, joints_deg: [0, 90, 90, 30, -90, 90]}}
            - {{name: B, positon: [0.1, 0.2, 0.3]}}
        """)
    errs = errors(p)
    assert any(e.startswith(f"{p}:2:11: duration:") and "(got 'five')" in e for e in errs)
    assert any(e.startswith(f"{p}:6:17: task.targets.1.positon: unknown field") and "'position'" in e for e in errs)


def test_errors_in_a_base_file_point_into_the_base(tmp_path):
    base = write(tmp_path, HIT.read_text().replace("kp: [900", "kpp: [900"), "base.yaml")
    child = write(tmp_path, "extends: base.yaml\nseed: 3\n", "child.yaml")
    (err,) = errors(child)
    line = next(i for i, text in enumerate(base.read_text().splitlines(), 1) if "kpp:" in text)
    assert err.startswith(f"{base}:{line}:3: controller.kpp: unknown field")


def test_missing_section_and_cross_references(tmp_path):
    p = write(tmp_path, """\
        robot: {type: hit}
        planner: {type: multi-cubic, segment_durations: [1]}
        controller: {type: joint-pd}
        task:
          targets: [{name: A, joints_deg: [0, 0, 0, 0, 0, 0]}]
          sequence: [A, Z]
        """)
    errs = errors(p)
    assert any("missing required field 'duration'" in e for e in errs)
    assert any("unknown target name(s) ['Z']" in e and ":4:" in e for e in errs)


def test_duplicate_keys_are_errors(tmp_path):
    p = write(tmp_path, "robot: {type: hit}\nseed: 1\nseed: 2\n")
    (err,) = errors(p)
    assert err.startswith(f"{p}:3:1: seed: duplicate key")


def test_yaml_syntax_error_is_located(tmp_path):
    p = write(tmp_path, "robot:\n  type: hit\n  l1: [0.3\n")
    (err,) = errors(p)
    assert err.startswith(f"{p}:4:1: YAML syntax: a list in [brackets] not closed: end it with ']'")


@pytest.mark.parametrize("text, where, says", [
    ("name: x\nrobot:\n\ttype: hit\n", "3:1", "a tab: YAML indents with spaces only"),
    ("name: x\nrobot:\n  type: hit\n   planner: {type: a}\n", "4:11", "usually this line is indented deeper than "
     "the key above it"),
    ("name: x\nrobot:\n  type: hit\n ee: 1\n", "4:2", "this line's indentation does not match its section's"),
    ("name: x\nrobot: {type: hit\n", "3:1", "a mapping in {braces} not closed"),
    # (PyYAML notices a missing ': ' on the line after: said at the line missing it)
    ("name: x\nrobot:\n  type: dh\n  name:arm3\n  convention: standard\n", "4:3",
     "a ':' missing, or the space after it"),
    ("name: x\ncontroller: {type:joint-pd, kp: 1}\n", "2:14", "'type:joint-pd' is one key with no value: a ':' "
     "needs a space after it (`type: joint-pd`)"),
])
def test_yaml_syntax_is_said_in_plain_words_with_its_usual_cause(tmp_path, text, where, says):
    """PyYAML's own words ('mapping values are not allowed in this context') stay, in parentheses, after them."""
    p = tmp_path / "s.yaml"
    p.write_text(text)
    (err,) = errors(p)
    assert err.startswith(f"{p}:{where}: ") and says in err


def test_extends_merges_deeply_and_null_deletes(tmp_path):
    p = write(tmp_path, f"""\
        extends: {HIT}
        controller: {{kp: 50}}
        expect:
          contact_steps: null
        """)
    sc = load_scenario(p).model
    assert sc.controller.kp == 50 and sc.controller.kd == [45, 45, 8, 9, 0.8, 0.9]
    assert "contact_steps" not in sc.expect and "tracking_rms_deg" in sc.expect


def test_changing_a_plugin_type_replaces_its_section():
    base = {"planner": {"type": "multi-cubic", "segment_durations": [1]}}
    assert deep_merge(base, {"planner": {"type": "min-jerk", "segment_durations": [2]}}) == \
        {"planner": {"type": "min-jerk", "segment_durations": [2]}}


def test_circular_extends(tmp_path):
    write(tmp_path, "extends: b.yaml\n", "a.yaml")
    write(tmp_path, "extends: a.yaml\n", "b.yaml")
    (err,) = errors(tmp_path / "a.yaml")
    assert err.startswith(f"{tmp_path / 'b.yaml'}:1:10: extends: circular extends: ")  # (the line closing it)
    assert err.split(": circular extends: ")[1].startswith(" -> ".join(str(tmp_path / f) for f in ("a.yaml", "b.yaml",
                                                                                                    "a.yaml")))


def test_set_overrides_parse_yaml_values_and_index_lists():
    sc = load_scenario(HIT, ["planner.segment_durations=[1, 1.5, 1, 1.5]", "seed=7",
                             "task.targets.1.position=[-0.4, -0.1, -0.3]", "controller.feedforward=gravity"]).model
    assert sc.planner.segment_durations == [1, 1.5, 1, 1.5] and sc.seed == 7
    assert sc.task.targets[1].position == (-0.4, -0.1, -0.3) and sc.controller.feedforward == "gravity"
    bracketed = load_scenario(HIT, ["task.targets[1].position=[-0.4, -0.1, -0.25]", "duration=1e1"]).model
    assert bracketed.task.targets[1].position == (-0.4, -0.1, -0.25) and bracketed.duration == 10.0  # (YAML 1.2)


def test_bad_set_override_is_reported_as_such():
    (err,) = errors(HIT, ["planner.segment_durations=fast"])
    assert err.startswith("<--set planner.segment_durations>") and "valid list" in err
    (err,) = errors(HIT, ["task.targets.9.name=X"])
    assert "not an index" in err


def test_scenario_model_json_schema_includes_plugins():
    from rehabkit.core.plugins.registry import default_registry
    from rehabkit.core.scenario.models import scenario_model

    schema = scenario_model(default_registry()).model_json_schema()
    assert {"robot", "planner", "controller", "task", "expect"} <= set(schema["properties"])
    defs = str(schema["$defs"])
    assert "segment_durations" in defs and "counts_per_rev" in defs


def test_extends_resolves_each_files_relative_paths_from_that_file(tmp_path):
    """A base file's ``patient: patients/p01.yaml`` and a robot's ``file: arm4.urdf`` mean the files beside the
    base, wherever the scenario extending it lives; the extending file's own relative paths stay its own."""
    from rehabkit.core.run.runner import Runner

    ROBOTS = SCENARIOS.parent / "examples" / "robots"
    study = tmp_path / "study" / "deeper"
    study.mkdir(parents=True)
    (study / "lexos_again.yaml").write_text(f"extends: {SCENARIOS / 'lexos_patient.yaml'}\nduration: 1.0\n"
                                            "expect: {}\n")
    loaded = load_scenario(study / "lexos_again.yaml")
    assert loaded.model.patient.id == "P01"  # from scenarios/patients/, not study/deeper/patients/
    (study / "arm.yaml").write_text(f"extends: {ROBOTS / 'urdf_arm4.yaml'}\nduration: 0.5\nexpect: {{}}\n")
    arm = load_scenario(study / "arm.yaml")
    assert arm.model.robot.file == str((ROBOTS / "arm4.urdf").resolve())
    assert Runner(arm).run().summary["metrics"]["sim_time_s"] == pytest.approx(0.5)
    (study / "arm4.urdf").write_text((ROBOTS / "arm4.urdf").read_text())
    (study / "own.yaml").write_text(f"extends: {ROBOTS / 'urdf_arm4.yaml'}\nrobot: {{file: arm4.urdf}}\n")
    assert load_scenario(study / "own.yaml").model.robot.file == "arm4.urdf"  # its own: from its own folder
