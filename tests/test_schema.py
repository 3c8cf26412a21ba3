"""`rehabkit schema` read by an independent validator (check-jsonschema, as an editor's YAML language server reads
it): every shipped scenario that `rehabkit validate` accepts is accepted, `extends:` files and `null` deletions
included; of the corpus of wrong files (all refused by validate), those whose mistake a schema can tell are refused,
a misspelt plugin named as such; a number in quotes is refused by both."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from rehabkit.cli import main
from tests.conftest import SCENARIOS
from tests.test_cli import cli

# the module's tests read one check-jsonschema verdict over every file (the `verdicts` fixture, ~2.7 s): on one
# pytest-xdist worker, so it is made once
pytestmark = pytest.mark.xdist_group("schema")
ROOT = SCENARIOS.parent
SHIPPED = sorted(p for d in (SCENARIOS, ROOT / "examples") for p in d.rglob("*.yaml") if "patients" not in p.parts)
CORPUS = sorted((ROOT / "tests" / "bad_scenarios").glob("*.yaml"))
NEEDS_EXAMPLE_PACKAGES = {"planar_lab.yaml", "hit_minjerk.yaml"}  # their plugins come from examples/ packages
CHECKED = [p for p in SHIPPED if p.name not in NEEDS_EXAMPLE_PACKAGES]
# wrong files the schema refuses: unknown keys and plugins, wrong value types, values out of a declared range,
# missing sections, unreadable YAML; the rest are mistakes only the run's setup can see (a joint's range, a body's
# name, a NaN gain, list lengths that depend on the robot)
SCHEMA_REFUSES = {
    "cartesian_speed_zero", "control_rate_zero", "controller_needs_floating_base", "dh_convention",
    "dh_mass_negative", "dh_row_unknown_key", "dh_velocity_zero", "duration_bool", "duration_negative",
    "duration_quoted",
    "duration_text", "empty_file", "event_time_negative", "expect_text", "expect_unknown_operator",
    "load_force_two_values", "log_rate_negative", "missing_robot", "not_utf8", "ompl_algorithm", "ompl_time_zero",
    "safety_margin_negative", "seed_fraction", "segments_empty", "sensor_rate_text", "stop_category_rule_misspelt",
    "stop_category_three", "target_free_axes_bad", "target_position_short", "top_level_list",
    "unknown_controller_field", "unknown_planner", "unknown_robot_type", "unknown_sensor", "unknown_top_key",
    "weakness_above_one", "world_negative_size", "world_shape", "yaml_syntax", "yaml_tab",
}


@pytest.fixture(scope="module")
def schema(tmp_path_factory):
    path = tmp_path_factory.mktemp("schema") / "rehabkit.schema.json"
    done = cli("schema")  # the command's own main in this process: a second Python only to print it cost ~2 s
    assert done.returncode == 0, done.stderr
    path.write_text(done.stdout)
    return path


@pytest.fixture(scope="module")
def extending(tmp_path_factory) -> dict[str, Path]:
    """Files that extend a shipped scenario: one partial but right, one with a misspelt section, one a wrong type."""
    folder = tmp_path_factory.mktemp("extending")
    texts = {"longer": f"extends: {SCENARIOS / 'lexos_patient.yaml'}\nduration: 30\ncontroller: {{kp: 200}}\n"
                       "expect: {searched_legs: null}\n",
             "typo": f"extends: {SCENARIOS / 'lexos_patient.yaml'}\ncontroler: {{kp: 200}}\n",
             "wrong_type": f"extends: {SCENARIOS / 'hit_roundtrip.yaml'}\nduration: soon\n"}
    for name, text in texts.items():
        (folder / f"{name}.yaml").write_text(text)
    return {name: folder / f"{name}.yaml" for name in texts}


@pytest.fixture(scope="module")
def verdicts(schema, extending) -> dict[str, list[dict]]:
    """check-jsonschema's verdict on every file the tests below read, from one call: each call first checks the
    schema itself against JSON Schema's metaschema (~1 s), the same check every time. The tests pick their files'
    verdicts out of it (a file's verdict does not depend on the others checked with it)."""
    return _refused(schema, [*CHECKED, *CORPUS, *extending.values()])


def _refused(schema, files) -> dict[str, list[dict]]:
    """check-jsonschema's verdict: file (as given) → its errors (a file that cannot be parsed: one error)."""
    done = subprocess.run([shutil.which("check-jsonschema"), "--schemafile", str(schema), "--output-format", "json",
                           *map(str, files)], capture_output=True, text=True, timeout=300)
    report = json.loads(done.stdout)
    out: dict[str, list[dict]] = {}
    for e in report.get("errors", []) + report.get("parse_errors", []):  # (an empty list is left out)
        out.setdefault(e["filename"], []).append(e)
    return out


def _of(verdicts, files) -> dict[str, list[dict]]:
    """The verdicts on ``files``, by file name."""
    wanted = {str(p) for p in files}
    return {name.rsplit("/", 1)[-1]: errors for name, errors in verdicts.items() if name in wanted}


def test_every_shipped_scenario_validate_accepts_the_schema_accepts(verdicts, capsys):
    accepted = [p for p in CHECKED if main(["validate", str(p)]) == 0]
    capsys.readouterr()
    assert len(accepted) >= 21 and any("extends:" in p.read_text() for p in accepted)
    assert _of(verdicts, accepted) == {}


def test_the_schema_refuses_the_wrong_files_it_can_tell_and_names_the_plugin(verdicts):
    refused = _of(verdicts, CORPUS)
    assert {name.removesuffix(".yaml") for name in refused} == SCHEMA_REFUSES
    (planner,) = refused["unknown_planner.yaml"]  # `type: multicubic`: the choices, not another plugin's fields
    assert planner["path"] == "$.planner.type" and "'multi-cubic'" in planner["message"]
    assert "'feedfoward' was unexpected" in refused["unknown_controller_field.yaml"][0]["message"]


def test_an_extending_file_is_partial_and_null_deletes(extending, verdicts, capsys):
    good, typo, wrong_type = extending["longer"], extending["typo"], extending["wrong_type"]
    assert main(["validate", str(good)]) == 0 and main(["validate", str(typo)]) == 2
    assert main(["validate", str(wrong_type)]) == 2
    capsys.readouterr()
    refused = _of(verdicts, [good, typo, wrong_type])
    assert set(refused) == {"typo.yaml", "wrong_type.yaml"}
    assert "'controler' was unexpected" in json.dumps(refused["typo.yaml"])


def test_every_bound_is_written_in_json_schemas_own_words(schema):
    """A bound on a union (``scale: float | list[float]`` with ``gt=0``) came out as pydantic's own ``gt``, which
    JSON Schema validators ignore: an editor let ``scale: 2`` through. Every bound is ``minimum``,
    ``exclusiveMinimum``, … (``gt``/``ge``/``lt``/``le`` stay only as the names of ``expect:``'s fields)."""
    misplaced = []

    def walk(node, at):
        if isinstance(node, dict):
            for key, value in node.items():
                if key in ("gt", "ge", "lt", "le") and not isinstance(value, dict):
                    misplaced.append(f"{at}/{key}")
                walk(value, f"{at}/{key}")
        elif isinstance(node, list):
            for i, value in enumerate(node):
                walk(value, f"{at}/{i}")

    doc = json.loads(schema.read_text())
    walk(doc, "")
    assert misplaced == []
    scale = doc["$defs"]["ActionSpec"]["properties"]["scale"]["anyOf"]
    assert scale[0] == {"exclusiveMinimum": 0.0, "maximum": 1.0, "type": "number"}
