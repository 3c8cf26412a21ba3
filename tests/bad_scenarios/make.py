"""Writes the corpus of bad scenarios (``python tests/bad_scenarios/make.py``): each file is a good scenario with
one mistake a careless user makes, its first line saying which. ``tests/test_bad_corpus.py`` checks that
``rehabkit validate`` refuses every one, located (file:line:col, exit 2), and that ``rehabkit run`` never exits 1.
"""

from pathlib import Path

HERE = Path(__file__).parent

ARM3 = (HERE.parent / "data" / "arm3_dh.yaml").read_text()  # a 3-joint DH arm (tests/test_user_robot_errors)

URDF = (HERE.parents[1] / "examples" / "robots" / "urdf_arm4.yaml").read_text().replace(
    "file: arm4.urdf", "file: ../../examples/robots/arm4.urdf")
DH_BOXES = (HERE.parents[1] / "examples" / "robots" / "dh_arm3.yaml").read_text()
DYNO = (HERE.parents[1] / "examples" / "robots" / "elbow_dynamometer.yaml").read_text()  # MyoElbow strapped in
STRAP = "straps: [{segment: forearm, body: elbow_link, position: [0.18, 0, 0]}]"
DRIVE = "    drive: {participation"  # (a line of the patient's model to put a setting before)

# name: (what is wrong, base, [(old, new), ...])
CASES: dict[str, tuple[str, str, list[tuple[str, str]]]] = {
    "unknown_top_key": ("a misspelt top-level key", ARM3, [("duration: 4.5", "duraton: 4.5")]),
    "unknown_planner": ("a misspelt planner", ARM3, [("type: multi-cubic", "type: multicubic")]),
    "unknown_controller_field": ("a misspelt controller setting", ARM3,
                                 [("feedforward: inverse", "feedfoward: inverse")]),
    "unknown_robot_type": ("a robot type that does not exist", ARM3, [("type: dh", "type: dhh")]),
    "unknown_sensor": ("a sensor type that does not exist", ARM3,
                       [("duration: 4.5", "sensors:\n  enc: {type: joint-encoders}\nduration: 4.5")]),
    "duration_text": ("a word for a number", ARM3, [("duration: 4.5", "duration: five")]),
    "duration_quoted": ("a number in quotes", ARM3, [("duration: 4.5", 'duration: "4.5"')]),
    "duration_bool": ("a YAML boolean for a number", ARM3, [("duration: 4.5", "duration: yes")]),
    "duration_inf": ("an infinite duration", ARM3, [("duration: 4.5", "duration: .inf")]),
    "duration_negative": ("a negative duration", ARM3, [("duration: 4.5", "duration: -4.5")]),
    "duration_huge": ("a duration whose record cannot fit in memory", ARM3, [("duration: 4.5", "duration: 1e9")]),
    "seed_fraction": ("a fractional seed", ARM3, [("duration: 4.5", "seed: 1.5\nduration: 4.5")]),
    "kp_short": ("gains for two joints of three", ARM3, [("kp: [300, 300, 150]", "kp: [300, 300]")]),
    "kd_nan": ("a NaN gain", ARM3, [("kd: [20, 20, 8]", "kd: [20, .nan, 8]")]),
    "kp_negative": ("a negative gain", ARM3, [("kp: [300, 300, 150]", "kp: [300, -300, 150]")]),
    "gains_auto_and_kp": ("hand gains beside gains: auto", ARM3,
                          [("  kp: [300, 300, 150]\n", "  gains: auto\n  kp: [300, 300, 150]\n")]),
    "bandwidth_too_high": ("a PD bandwidth the control period cannot give", ARM3,
                           [("  kp: [300, 300, 150]\n  kd: [20, 20, 8]\n", "  gains: auto\n  bandwidth_hz: 200\n")]),
    "target_joints_short": ("joint values for two joints of three", ARM3,
                            [("{name: B, joints_deg: [40, 60, 20]}", "{name: B, joints_deg: [40, 60]}")]),
    "target_beyond_range": ("a joint target beyond a joint's range", ARM3,
                            [("{name: B, joints_deg: [40, 60, 20]}", "{name: B, joints_deg: [40, 160, 20]}")]),
    "target_two_kinds": ("a target with joint values and a position", ARM3,
                         [("{name: B, joints_deg: [40, 60, 20]}",
                           "{name: B, joints_deg: [40, 60, 20], position: [0.3, 0, 0.2]}")]),
    "target_no_kind": ("a target with nothing to reach", ARM3, [("{name: B, joints_deg: [40, 60, 20]}", "{name: B}")]),
    "target_rpy_alone": ("an orientation without a position", ARM3,
                         [("{name: B, joints_deg: [40, 60, 20]}", "{name: B, rpy_deg: [0, 0, 0]}")]),
    "target_free_axes_alone": ("free_axes without an orientation", ARM3,
                               [("{name: B, joints_deg: [40, 60, 20]}",
                                 "{name: B, position: [0.3, 0, 0.3], free_axes: z}")]),
    "target_free_axes_bad": ("free_axes naming an axis that is not one", ARM3,
                             [("{name: B, joints_deg: [40, 60, 20]}",
                               "{name: B, position: [0.3, 0, 0.3], rpy_deg: [0, 0, 0], free_axes: w}")]),
    "target_out_of_reach": ("a Cartesian target beyond the arm's reach", ARM3,
                            [("{name: B, joints_deg: [40, 60, 20]}", "{name: B, position: [1.5, 0, 0.3]}")]),
    "target_position_short": ("a position with two coordinates", ARM3,
                              [("{name: B, joints_deg: [40, 60, 20]}", "{name: B, position: [0.3, 0.1]}")]),
    "target_duplicate_name": ("two targets with one name", ARM3,
                              [("{name: B, joints_deg: [40, 60, 20]}", "{name: A, joints_deg: [40, 60, 20]}")]),
    "same_as_unknown": ("same_as naming no target", ARM3,
                        [("{name: B, joints_deg: [40, 60, 20]}", "{name: B, same_as: Z}")]),
    "orientation_of_unknown": ("orientation_of naming no target", ARM3,
                               [("{name: B, joints_deg: [40, 60, 20]}",
                                 "{name: B, position: [0.3, 0, 0.3], orientation_of: Z}")]),
    "sequence_unknown": ("a sequence naming no target", ARM3,
                         [("    - {name: B, joints_deg: [40, 60, 20]}\n",
                           "    - {name: B, joints_deg: [40, 60, 20]}\n  sequence: [A, C]\n")]),
    "start_unknown": ("a start naming no target", ARM3,
                      [("    - {name: B, joints_deg: [40, 60, 20]}\n",
                        "    - {name: B, joints_deg: [40, 60, 20]}\n  start: Z\n")]),
    "event_unknown_target": ("an event waiting for a target that does not exist", ARM3,
                             [("    - {name: B, joints_deg: [40, 60, 20]}\n",
                               "    - {name: B, joints_deg: [40, 60, 20]}\n  events:\n    - {reached: Z}\n")]),
    "event_two_triggers": ("an event with two triggers", ARM3,
                           [("    - {name: B, joints_deg: [40, 60, 20]}\n",
                             "    - {name: B, joints_deg: [40, 60, 20]}\n  events:\n    - {at: 1, reached: B}\n")]),
    "event_move_no_object": ("a move event with no object", ARM3,
                             [("    - {name: B, joints_deg: [40, 60, 20]}\n",
                               "    - {name: B, joints_deg: [40, 60, 20]}\n  events:\n    - {at: 1, action: move}\n")]),
    "event_planner_unknown_field": ("an event's planner setting the planner does not have", ARM3,
                                    [("    - {name: B, joints_deg: [40, 60, 20]}\n",
                                      "    - {name: B, joints_deg: [40, 60, 20]}\n  events:\n"
                                      "    - {at: 1, action: replan, planner: {segment_duration: [2]}}\n")]),
    "event_planner_type": ("an event changing the planner's type", ARM3,
                           [("    - {name: B, joints_deg: [40, 60, 20]}\n",
                             "    - {name: B, joints_deg: [40, 60, 20]}\n  events:\n"
                             "    - {at: 1, action: replan, planner: {type: cartesian}}\n")]),
    "event_time_negative": ("an event before the start", ARM3,
                            [("    - {name: B, joints_deg: [40, 60, 20]}\n",
                              "    - {name: B, joints_deg: [40, 60, 20]}\n  events:\n    - {at: -1, action: stop}\n")]),
    "segments_too_many": ("more segment durations than segments", ARM3,
                          [("segment_durations: [2]", "segment_durations: [2, 2]")]),
    "segments_negative": ("a negative segment duration", ARM3, [("segment_durations: [2]", "segment_durations: [-2]")]),
    "segments_empty": ("no segment durations", ARM3, [("segment_durations: [2]", "segment_durations: []")]),
    "dh_row_unknown_key": ("a DH row with a misspelt key", ARM3, [("{a: 0.3}", "{a: 0.3, alpha: 90}")]),
    "dh_rows_vs_joints": ("three DH rows and two joints", ARM3,
                          [("    - {name: elbow, range_deg: [-150, 150], velocity_deg_s: 150, effort: 20, mass: 0.8}\n",
                            "")]),
    "dh_range_reversed": ("a joint range given upper first", ARM3,
                          [("range_deg: [-120, 120]", "range_deg: [120, -120]")]),
    "dh_velocity_zero": ("a joint that may not move", ARM3, [("velocity_deg_s: 150", "velocity_deg_s: 0")]),
    "dh_mass_negative": ("a negative link mass", ARM3, [("mass: 0.8", "mass: -0.8")]),
    "dh_convention": ("a DH convention that does not exist", ARM3,
                      [("convention: standard", "convention: craig")]),
    "world_box_sizes": ("a box with two sizes", ARM3,
                        [("planner:", "world:\n  objects: [{name: box, shape: box, size: [0.1, 0.1]}]\nplanner:")]),
    "world_negative_size": ("an object of negative size", ARM3,
                            [("planner:", "world:\n  objects: [{name: ball, shape: sphere, size: [-0.1]}]\nplanner:")]),
    "world_name_floor": ("an object named like the scene's floor", ARM3,
                         [("planner:", "world:\n  objects: [{name: floor, shape: sphere, size: [0.1],"
                           " pose: {position: [1, 1, 1]}}]\nplanner:")]),
    "world_name_robot": ("an object named like a robot link", ARM3,
                         [("planner:", "world:\n  objects: [{name: elbow_link, shape: sphere, size: [0.1],"
                           " pose: {position: [1, 1, 1]}}]\nplanner:")]),
    "world_duplicate": ("two objects with one name", ARM3,
                        [("planner:", "world:\n  objects:\n    - {name: b, shape: sphere, size: [0.1]}\n"
                          "    - {name: b, shape: sphere, size: [0.1]}\nplanner:")]),
    "world_shape": ("a shape MuJoCo does not have here", ARM3,
                    [("planner:", "world:\n  objects: [{name: b, shape: cone, size: [0.1]}]\nplanner:")]),
    "control_rate_vs_timestep": ("a control rate the timestep cannot give", ARM3,
                                 [("duration: 4.5", "rates: {control_hz: 300}\nduration: 4.5")]),
    "control_rate_zero": ("a control rate of zero", ARM3, [("duration: 4.5", "rates: {control_hz: 0}\nduration: 4.5")]),
    "log_rate_negative": ("a negative logging rate", ARM3,
                          [("duration: 4.5", "logging: {rate_hz: -10}\nduration: 4.5")]),
    "sensor_rate_text": ("a sensor rate in words", ARM3,
                         [("duration: 4.5", "sensors:\n  enc: {type: joint-encoder, rate_hz: fast}\nduration: 4.5")]),
    "safety_margin_negative": ("a negative position margin", ARM3,
                               [("duration: 4.5", "safety: {position_margin_deg: -1}\nduration: 4.5")]),
    "safety_unknown_joint": ("envelope limits for a joint the robot does not have", ARM3,
                             [("duration: 4.5", "safety:\n  joints: {wrist: {velocity_deg_s: 30}}\nduration: 4.5")]),
    "safety_range_reversed": ("an envelope range given upper first", ARM3,
                              [("duration: 4.5", "safety:\n  joints: {elbow: {range_deg: [90, -90]}}\nduration: 4.5")]),
    "keep_in_reversed": ("a keep-in box whose min exceeds its max", ARM3,
                         [("duration: 4.5", "safety:\n  keep_in: {min: [1, -1, 0], max: [-1, 1, 2]}\nduration: 4.5")]),
    "force_limit_no_source": ("an interaction-force limit with nothing to measure the force", ARM3,
                              [("duration: 4.5", "safety: {interaction_force_n: 50}\nduration: 4.5")]),
    "expect_unknown_metric": ("an expectation on a metric no plugin reports", ARM3,
                              [("tracking_max_deg: {lt: 2}", "tracking_max: {lt: 2}")]),
    "expect_unknown_operator": ("an expectation with an unknown comparison", ARM3,
                                [("tracking_max_deg: {lt: 2}", "tracking_max_deg: {less: 2}")]),
    "expect_text": ("an expectation against a word", ARM3,
                    [("tracking_max_deg: {lt: 2}", "tracking_max_deg: {lt: two}")]),
    "planner_needs_workspace": ("a planner needing a workspace table on a robot without one", ARM3,
                                [("{type: multi-cubic, segment_durations: [2]}", "{type: voxel-astar}")]),
    "planner_needs_cluster_points": ("a planner needing cluster points on a robot without them", ARM3,
                                     [("{type: multi-cubic, segment_durations: [2]}", "{type: rrt-ga}")]),
    "controller_needs_floating_base": ("a whole-body controller on a fixed arm", ARM3,
                                       [("  type: joint-pd\n  kp: [300, 300, 150]\n  kd: [20, 20, 8]\n"
                                         "  feedforward: inverse-dynamics\n", "  type: qp-stack\n")]),
    "reference_mismatch": ("a Cartesian-reference controller after a joint-space planner", ARM3,
                           [("  type: joint-pd\n  kp: [300, 300, 150]\n  kd: [20, 20, 8]\n"
                             "  feedforward: inverse-dynamics\n", "  type: clik-pd\n")]),
    "ompl_time_zero": ("no planning time", ARM3,
                       [("{type: multi-cubic, segment_durations: [2]}", "{type: ompl-joint, time_limit_s: 0}")]),
    "ompl_algorithm": ("an OMPL planner rehabkit does not offer", ARM3,
                       [("{type: multi-cubic, segment_durations: [2]}", "{type: ompl-joint, algorithm: rrt}")]),
    "ompl_start_in_obstacle": ("a start posture inside an obstacle", ARM3,
                               [("{type: multi-cubic, segment_durations: [2]}", "{type: ompl-joint}"),
                                ("  base: {position: [0, 0, 0.5]}\n", "  base: {position: [0, 0, 0.5]}\nworld:\n"
                                 "  objects: [{name: wall, shape: box, size: [0.05, 0.3, 0.3],"
                                 " pose: {position: [0.2, 0, 1.0]}}]\n")]),
    "cartesian_through_obstacle": ("a straight line through an obstacle (no via point)", DH_BOXES,
                                   [("{type: ompl-joint, algorithm: rrt-connect}", "{type: cartesian}"),
                                    ("    - {name: V, position: [0.05, 0.0, 0.45]}\n", "")]),
    "cartesian_speed_zero": ("a hand speed of zero", ARM3,
                             [("{type: multi-cubic, segment_durations: [2]}", "{type: cartesian, speed_m_s: 0}")]),
    "urdf_missing": ("a robot model file that is not there", URDF, [("arm4.urdf", "arm5.urdf")]),
    "urdf_ee_unknown": ("an end effector the model does not have", URDF, [("ee_frame: tip", "ee_frame: tool")]),
    "urdf_limits_unknown_joint": ("limits for a joint the model does not have", URDF,
                                  [("  ee_frame: tip\n",
                                    "  ee_frame: tip\n  limits: {wrist2: {velocity_deg_s: 90}}\n")]),
    "patient_missing": ("a patient profile file that is not there", ARM3,
                        [("duration: 4.5", "patient: patients/nobody.yaml\nduration: 4.5")]),
    "extends_missing": ("a base file that is not there", ARM3,
                        [("name: my-arm3", "extends: base.yaml\nname: my-arm3")]),
    "yaml_syntax": ("an unclosed bracket", ARM3, [("kd: [20, 20, 8]", "kd: [20, 20, 8")]),
    "yaml_tab": ("a tab in the indentation", ARM3, [("  kd: [20, 20, 8]", "\tkd: [20, 20, 8]")]),
    "top_level_list": ("a list where the scenario's mapping belongs", "- name: my-arm3\n- duration: 4.5\n", []),
    "empty_file": ("nothing in the file", "", []),
    "missing_robot": ("no robot section", ARM3, [(ARM3[ARM3.index("robot:"):ARM3.index("planner:")], "")]),
    "strap_body_misspelt": ("a strap on a body the robot does not have", DYNO,
                            [("body: elbow_link", "body: elbo_link")]),
    "strap_twice": ("two straps on one segment", DYNO,
                    [(STRAP, STRAP.replace("}]", "}, {segment: forearm, body: elbow_link, position: [0.1, 0, 0]}]"))]),
    "fit_forward_zero": ("a zero forward direction", DYNO, [("forward: [0.9987, 0.0, -0.0501]", "forward: [0, 0, 0]")]),
    "weakness_above_one": ("a force scale above full strength", DYNO,
                           [(DRIVE, "    weakness: {elbow_flexors: 1.5}\n" + DRIVE)]),
    "muscle_group_unknown": ("a misspelt muscle group", DYNO,
                             [(DRIVE, "    weakness: {elbow_flexor: 0.5}\n" + DRIVE)]),
    "contracture_unknown_joint": ("a contracture of a joint MyoElbow does not have", DYNO,
                                  [(DRIVE, "    contracture_deg: {wrist_flexion: [0, 10]}\n" + DRIVE)]),
    "myoelbow_upper_arm_strap": ("an upper-arm strap on MyoElbow, whose upper arm is fixed", DYNO,
                                 [("segment: forearm", "segment: upper_arm")]),
    "musculoskeletal_left_side": ("a left-side profile for the right-arm models", DYNO,
                                  [("side: right", "side: left")]),
    "stop_category_rule_misspelt": ("a stop category for a rule that does not exist", ARM3,
                                    [("duration: 4.5", "safety: {stop_category: {estop: 1}}\nduration: 4.5")]),
    "stop_category_three": ("a stop category IEC 60204-1 does not have", ARM3,
                            [("duration: 4.5", "safety: {stop_category: {default: 3}}\nduration: 4.5")]),
    "load_on_missing_body": ("a test rig's load on a body the scene does not have", ARM3,
                             [("duration: 4.5", "world:\n  loads: [{name: push, body: hand, force_n: [0, 0, -10]}]\n"
                               "duration: 4.5")]),
    "force_limit_without_source": ("an interaction-force limit with nothing to measure the force", ARM3,
                                   [("duration: 4.5", "safety: {interaction_force_n: 40}\nduration: 4.5")]),
    "load_force_two_values": ("a force vector with two components, over an extended file's three", ARM3,
                              [("duration: 4.5", "world:\n  loads: [{name: push, body: elbow_link, force_n: [0, 60]}]\n"
                                "duration: 4.5")]),
    "force_sensor_body_misspelt": ("a force sensor on a body the robot does not have", ARM3,
                                   [("duration: 4.5", "sensors:\n  ft: {type: force-torque, body: elbow_lnk}\n"
                                     "duration: 4.5")]),
    "force_sensor_unknown_strap": ("a force sensor at a strap the robot does not have", ARM3,
                                   [("duration: 4.5", "sensors:\n  cuff: {type: force-torque, strap: forearm}\n"
                                     "duration: 4.5")]),
}


def main() -> None:
    for old in HERE.glob("*.yaml"):
        old.unlink()
    for name, (what, base, edits) in CASES.items():
        text = base
        for old, new in edits:
            assert old in text, (name, old)
            text = text.replace(old, new, 1)
        (HERE / f"{name}.yaml").write_text(f"# bad: {what}\n" + text)
    # bytes that are not UTF-8 (a file saved as Latin-1 with an accented name)
    (HERE / "not_utf8.yaml").write_bytes(b"# bad: a file that is not UTF-8\n" + ARM3.replace(
        "name: my-arm3", "name: bras-\xe9paule").encode("latin-1"))
    print(f"{len(CASES) + 1} bad scenarios in {HERE}")


if __name__ == "__main__":
    main()
