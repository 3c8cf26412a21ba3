"""What a person sees when a run's recording opens in Rerun's viewer: the layout sent with it (a blueprint) and the
entities it shows, read back from the ``.rrd`` with Rerun's own reader."""

from __future__ import annotations

import numpy as np
import pytest
import rerun.chunk as rc

from rehabkit.testing import group
from tests.conftest import SCENARIOS

HIT = SCENARIOS / "hit_roundtrip.yaml"
LEXOS_MYOARM = SCENARIOS / "lexos_myoarm.yaml"


def _columns(chunk) -> dict[str, list]:
    """A chunk's component columns (not its row ids and timelines), each a list of rows."""
    batch, skip = chunk.to_record_batch(), set(chunk.timeline_names)
    return {name: batch.column(name).to_pylist() for name in batch.schema.names
            if name not in skip and not name.startswith("rerun.")}


def read_layout(rrd) -> tuple[list, dict[str, dict]]:
    """The blueprint's tree from its root (containers as ``(kind, name, [children])``, views as ``(class, name,
    origin, contents)``) and the views by id, as the viewer reads them from the file."""
    reader = rc.RrdReader(rrd)
    (store,) = reader.blueprints()
    parts: dict[str, dict[str, list]] = {}
    for chunk in reader.stream(store=store).to_chunks():
        for name, values in _columns(chunk).items():
            parts.setdefault(chunk.entity_path.strip("/"), {})[name] = values[-1]
    views = {}

    def node(path: str):
        p = parts[path]
        if path.startswith("container/"):
            kind = p["ContainerBlueprint:container_kind"][0]
            name = (p.get("ContainerBlueprint:display_name") or [None])[0]
            return ("container", kind, name, [node(c) for c in p["ContainerBlueprint:contents"]])
        contents = parts.get(f"{path}/ViewContents", {}).get("ViewContents:query", [])
        view = (p["ViewBlueprint:class_identifier"][0], p["ViewBlueprint:display_name"][0],
                p["ViewBlueprint:space_origin"][0], tuple(contents))
        views[path] = {"view": view, **parts.get(f"{path}/EyeControls3D", {})}
        return view

    (root,) = parts["viewport"]["ViewportBlueprint:root_container"]
    root_path = "container/" + "".join(f"{b:02x}" for b in root)
    root_path = next(p for p in parts if p.replace("-", "") == root_path)
    return node(root_path), views


class _Components(dict):
    """An entity's components (name -> every logged value in order), each turned into Python values when first read:
    a test reads a few of a recording's thousands of rows (turning them all took seconds of the suite)."""

    def __getitem__(self, name: str) -> list:
        value = super().__getitem__(name)
        if not isinstance(value, list):  # (the chunks' arrow columns, in order)
            value = [row for column in value.columns for row in column.to_pylist()]
            super().__setitem__(name, value)
        return value

    def get(self, name: str, default=None):
        return self[name] if name in self else default  # noqa: SIM401 (dict.get would skip the conversion)

    def values(self):
        return [self[name] for name in self]

    def items(self):
        return [(name, self[name]) for name in self]


class _Columns:
    def __init__(self):
        self.columns: list = []


def recording(rrd) -> dict[str, dict[str, list]]:
    """Each entity's static components and, for the rest, every logged value in order (path -> component -> list)."""
    reader = rc.RrdReader(rrd)
    (store,) = reader.recordings()
    out: dict[str, _Components] = {}
    for chunk in reader.stream(store=store).to_chunks():
        batch, skip = chunk.to_record_batch(), set(chunk.timeline_names)
        parts = out.setdefault(chunk.entity_path.strip("/"), _Components())
        for name in batch.schema.names:
            if name not in skip and not name.startswith("rerun."):
                dict.setdefault(parts, name, _Columns()).columns.append(batch.column(name))
    return out


def _flat(tree) -> list[tuple]:
    if tree[0] == "container":
        return [v for child in tree[3] for v in _flat(child)]
    return [tree]


def _run(path, overrides, out):
    """The run, and its plugins as they were built (to check the recording against)."""
    from rehabkit.core.run.runner import Runner
    from rehabkit.core.scenario.loader import load_scenario

    runner = Runner(load_scenario(path, overrides), out_dir=out)
    result = runner.run()
    result.setup = runner.setup
    return result


@pytest.fixture(scope="module")
def hit_rrd(tmp_path_factory):
    out = tmp_path_factory.mktemp("hit")
    return out / "run.rrd", _run(HIT, {"duration": 2.0}, out)


def test_the_recording_opens_with_a_scene_framed_on_the_robot_and_a_panel_per_joint(hit_rrd):
    rrd, result = hit_rrd
    tree, views = read_layout(rrd)
    flat = _flat(tree)
    joints = result.setup.robot.model.joint_names
    for j in joints:  # measured, reference and limits of the same joint, in one panel
        assert ("TimeSeries", f"{j} [deg]", f"joints/{j}", ("$origin/**",)) in flat
    assert any(v[0] == "TextLog" and v[2] == "events" for v in flat)
    (scene,) = [v for v in views.values() if v["view"][0] == "3D" and v["view"][2] == "world"]
    eye, target = np.array(scene["EyeControls3D:position"][0]), np.array(scene["EyeControls3D:look_target"][0])
    # framed on the robot (HIT spans ~0.8 m), not on the 6 x 6 m floor: the target among its bodies, the eye near
    bodies = np.array([result.setup.backend.body_poses().positions]).reshape(-1, 3)
    assert np.all(target >= bodies.min(axis=0) - 0.2) and np.all(target <= bodies.max(axis=0) + 0.2)
    assert 0.8 < np.linalg.norm(eye - target) < 3.0


def test_measured_and_reference_are_told_apart_by_name_colour_and_width_and_limits_are_drawn(hit_rrd):
    rrd, result = hit_rrd
    data = recording(rrd)
    model = result.setup.robot.model
    for i, j in enumerate(model.joint_names):
        measured, reference = data[f"joints/{j}/measured_deg"], data[f"joints/{j}/reference_deg"]
        assert measured["SeriesLines:names"] == [[f"{j} measured [deg]"]]
        assert reference["SeriesLines:names"] == [[f"{j} reference [deg]"]]
        assert measured["SeriesLines:colors"] != reference["SeriesLines:colors"]
        assert measured["SeriesLines:widths"][0][0] > reference["SeriesLines:widths"][0][0]
        q = np.array(measured["Scalars:scalars"]).ravel()
        assert np.allclose(q, np.degrees(result.trace.q[::10, i])[: len(q)], atol=1e-9)  # degrees, at the log rate
        limits = np.array(data[f"joints/{j}/limits_deg"]["Scalars:scalars"])
        assert np.allclose(limits[0], np.degrees([model.limits.lower[i], model.limits.upper[i]]))
    for series, unit in (("joint_velocity_deg_s", "deg/s"), ("joint_torque_nm", "N·m")):
        assert data[series]["SeriesLines:names"][0] == [f"{j} [{unit}]" for j in model.joint_names]


def test_the_text_log_ends_with_the_verdicts_the_terminal_prints(hit_rrd):
    rrd, result = hit_rrd
    lines = [text for batch in recording(rrd)["events"]["TextLog:text"] for text in batch]
    verdicts = [f"{'PASS' if e['passed'] else 'FAIL'}  {e['metric']}" for e in result.summary["expectations"]]
    assert verdicts and all(any(line.startswith(v) for line in lines) for v in verdicts)
    assert lines[-1] == ("run PASSED" if result.passed else "run FAILED")


def test_the_same_run_opens_with_the_same_layout(hit_rrd, tmp_path):
    from rehabkit.api import run_scenario

    rrd, _ = hit_rrd
    run_scenario(HIT, {"duration": 2.0}, out_dir=tmp_path)
    assert read_layout(tmp_path / "run.rrd")[0] == read_layout(rrd)[0]


def test_a_keep_in_breach_says_the_plan_warning_and_the_stop_with_its_fields_and_draws_the_box(tmp_path):
    breach = SCENARIOS.parent / "examples" / "hit_keep_in_breach.yaml"
    result = _run(breach, {}, tmp_path)
    data = recording(tmp_path / "run.rrd")
    events = data["events"]
    lines = [text for batch in events["TextLog:text"] for text in batch]
    levels = [level for batch in events["TextLog:level"] for level in batch]
    warning = result.summary["safety"]["plan_warnings"][0]["message"]
    assert levels[lines.index(f"PLAN {warning}")] == "WARN"
    trip = result.summary["safety"]["events"][0]
    (said,) = [line for line in lines if line.startswith(f"SAFETY {trip['rule']}") and trip["message"] in line]
    assert trip["joint"] is None or f"joint {trip['joint']}" in said
    assert trip["rule"] in [r for batch in events["rule"] for r in batch]  # the event's fields, beside its line
    lo, hi = result.setup.safety.keep_in
    box = data["world/safety/keep_in"]
    assert np.allclose(box["Boxes3D:centers"][0][0], (lo + hi) / 2)
    assert np.allclose(box["Boxes3D:half_sizes"][0][0], (hi - lo) / 2)


@pytest.mark.xdist_group(group(LEXOS_MYOARM))
def test_a_musculoskeletal_person_gets_panels_for_every_strap_and_muscle_group(scenario_run):
    r = scenario_run(LEXOS_MYOARM)  # (its scenario test's run)
    tree, _ = read_layout(r.out_dir / "run.rrd")
    flat = _flat(tree)
    logged = sorted(recording(r.out_dir / "run.rrd"))
    cuffs = tuple(p for p in logged if p.startswith("patient/cuff_force_n/"))
    muscles = tuple(p for p in logged if p.startswith("patient/activation/"))
    assert len(cuffs) == 2 and len(muscles) == 5  # (the upper arm's and the forearm's straps; the MyoArm's groups)
    assert ("TimeSeries", "cuff force [N]", "patient/cuff_force_n", cuffs) in flat
    assert ("TimeSeries", "activation", "patient/activation", muscles) in flat


def test_a_robot_whose_model_has_meshes_is_drawn_with_them(tmp_path):
    """An MJCF robot whose tool is a mesh (a tetrahedron, inline): its recording holds that mesh, vertex for
    vertex, on the tool's body — not a primitive standing in for it."""
    robots = SCENARIOS.parent / "examples" / "robots"
    xml = (robots / "arm5.xml").read_text()
    box = '<geom type="box" size="0.04 0.03 0.01" pos="0.04 0 0" mass="0.2"/>'
    assert box in xml
    vertices = [[0, 0, 0], [0.08, 0, 0], [0, 0.05, 0], [0, 0, 0.03]]
    mesh = " ".join(str(v) for p in vertices for v in p)
    # (the hand's inertia given: Pinocchio's MJCF parser and MuJoCo compute a mesh's otherwise — the load's check of
    # the two engines refuses the file without it)
    xml = xml.replace(box, '<inertial pos="0.03 0.01 0.01" mass="0.2" diaginertia="2e-4 2e-4 1e-4"/>'
                           '<geom type="mesh" mesh="tool_tip" rgba="0.9 0.6 0.1 1"/>')
    xml = xml.replace("<worldbody>", f'<asset><mesh name="tool_tip" vertex="{mesh}"/></asset>\n  <worldbody>', 1)
    (tmp_path / "arm5_mesh.xml").write_text(xml)
    scenario = (robots / "mjcf_arm5.yaml").read_text().replace("file: arm5.xml", "file: arm5_mesh.xml")
    (tmp_path / "arm.yaml").write_text(scenario)
    _run(tmp_path / "arm.yaml", {"duration": 0.2, "expect": None}, tmp_path / "out")
    data = recording(tmp_path / "out" / "run.rrd")
    (path,) = [p for p, c in data.items() if "Mesh3D:vertex_positions" in c]
    from scipy.spatial.transform import Rotation

    drawn = np.array(data[path]["Mesh3D:vertex_positions"][0])
    assert path.startswith("world/bodies/") and len(drawn) == 4
    # MuJoCo keeps a mesh in its principal frame, the geom's pose placing it: drawn so, in the body it is where
    # the file put it
    pose = data[path]
    rot = Rotation.from_quat(pose["Transform3D:quaternion"][0][0])  # (x, y, z, w)
    in_body = rot.apply(drawn) + pose["Transform3D:translation"][0][0]
    assert np.allclose(in_body, vertices, atol=1e-6)


@pytest.mark.xdist_group(group(LEXOS_MYOARM))
def test_cuff_forces_are_arrows_to_scale_at_the_rate_the_bones_move(scenario_run):
    r = scenario_run(LEXOS_MYOARM)
    data = recording(r.out_dir / "run.rrd")
    bones = len(data["world/end_effector"]["Points3D:positions"])  # a row per logged sample
    arrows = data["world/patient/cuffs/arrows"]
    assert len(arrows["Arrows3D:vectors"]) == bones
    vectors = np.array([v for row in arrows["Arrows3D:vectors"] for v in row])
    labels = [label for row in arrows["Arrows3D:labels"] for label in row]
    sizes = np.array([float(label.split()[-6]) for label in labels])  # "<segment> 12.3 N (1 cm per N)"
    assert all(label.endswith("N (1 cm per N)") for label in labels)
    assert np.allclose(np.linalg.norm(vectors, axis=1), sizes / 100, atol=0.0006)  # 1 cm per N, to the label's 0.1 N
    assert sizes.max() == pytest.approx(r.metrics["peak_cuff_force_n"], rel=0.05) and sizes.max() > 10


def test_angles_a_sensor_reads_in_radians_are_logged_in_degrees(hit_rrd):
    rrd, result = hit_rrd
    data = recording(rrd)
    assert "sensors/encoders/position_rad" not in data
    logged = np.array(data["sensors/encoders/position_deg"]["Scalars:scalars"])
    every = round(len(result.trace.q) / len(logged))  # (the encoder's rate)
    assert np.abs(logged - np.degrees(result.trace.q[::every][: len(logged)])).max() < 0.5


@pytest.mark.xdist_group(group(LEXOS_MYOARM))
def test_muscle_paths_move_with_the_bones_at_their_rate(scenario_run):
    """Every muscle path at every logged sample, each as it was then: a muscle's origin is a site on a bone, so in
    the frame of one of the logged bodies (their poses logged at the same instants) it stays put, to float32."""
    from scipy.spatial.transform import Rotation

    r = scenario_run(LEXOS_MYOARM)
    data = recording(r.out_dir / "run.rrd")
    samples = len(data["world/end_effector"]["Points3D:positions"])
    paths = data["world/patient/muscles/lines"]["LineStrips3D:strips"]
    assert len(paths) == samples and {len(row) for row in paths} == {63}  # (the MyoArm's muscles)
    origins = np.array([[strip[0] for strip in row] for row in paths])  # sample, muscle, xyz (world)
    bodies = {p: c for p, c in data.items() if p.startswith("world/bodies/") and "Transform3D:translation" in c
              and len(c["Transform3D:translation"]) == samples}
    # each body's poses over the samples, read once (not once per muscle: that was most of this test's time)
    poses = [(np.array([p[0] for p in pose["Transform3D:translation"]]),
              Rotation.from_quat([q[0] for q in pose["Transform3D:quaternion"]]).inv()) for pose in bodies.values()]
    moved = 0
    for k in range(origins.shape[1]):
        spread = [np.ptp(to_body.apply(origins[:, k] - where), axis=0).max() for where, to_body in poses]
        assert min(spread) < 2e-5, k  # fixed on a body
        moved += np.ptp(origins[:, k], axis=0).max() > 0.02
    assert moved > 30  # (most of them on bones that move centimetres)


def test_a_sensor_names_each_value_it_reads(hit_rrd):
    """The encoders' series are the joints' names with the unit, not numbers."""
    rrd, result = hit_rrd
    names = recording(rrd)["sensors/encoders/position_deg"]["SeriesLines:names"][0]
    assert names == [f"{j} position [deg]" for j in result.setup.robot.model.joint_names]


def test_a_urdf_robot_whose_link_is_a_mesh_file_is_drawn_with_it(tmp_path):
    """A URDF whose hand is an STL mesh file (a tetrahedron, written beside it): the recording holds that mesh, its
    vertices where the file put them in the hand's frame."""
    from scipy.spatial.transform import Rotation

    robots = SCENARIOS.parent / "examples" / "robots"
    urdf = (robots / "arm4.urdf").read_text()
    hand = '<origin xyz="0.05 0 0" rpy="0 1.5708 0"/><geometry><cylinder radius="0.02" length="0.1"/></geometry>'
    assert hand in urdf
    vertices = np.array([[0, 0, 0], [0.08, 0, 0], [0, 0.05, 0], [0, 0, 0.03]])
    faces = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
    import struct

    stl = bytearray(80) + struct.pack("<I", len(faces))  # binary STL, as MuJoCo reads it
    for f in faces:
        a, b, c = vertices[list(f)]
        n = np.cross(b - a, c - a)
        stl += struct.pack("<12fH", *(n / np.linalg.norm(n)), *a, *b, *c, 0)
    (tmp_path / "tool.stl").write_bytes(bytes(stl))
    (tmp_path / "arm4_mesh.urdf").write_text(urdf.replace(hand, '<geometry><mesh filename="tool.stl"/></geometry>'))
    scenario = (robots / "urdf_arm4.yaml").read_text().replace("file: arm4.urdf", "file: arm4_mesh.urdf")
    (tmp_path / "arm.yaml").write_text(scenario)
    _run(tmp_path / "arm.yaml", {"duration": 0.2, "expect": None, "world.objects": []}, tmp_path / "out")
    data = recording(tmp_path / "out" / "run.rrd")
    (path,) = [p for p, c in data.items() if "Mesh3D:vertex_positions" in c]
    assert path.startswith("world/bodies/hand/")
    drawn = np.array(data[path]["Mesh3D:vertex_positions"][0])
    pose = data[path]
    in_body = Rotation.from_quat(pose["Transform3D:quaternion"][0][0]).apply(drawn) + \
        pose["Transform3D:translation"][0][0]
    assert len(drawn) == 4 and np.allclose(np.sort(in_body, axis=0), np.sort(vertices, axis=0), atol=1e-6)
