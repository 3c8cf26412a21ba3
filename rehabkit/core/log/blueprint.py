"""The recording's layout, sent with it (a Rerun blueprint): what a person sees when the file opens in the viewer.

Built from what the recording holds, in a fixed order, so the same file opens the same way every time: the 3-D
scene framed on the robot, the person and the targets (not the whole floor); the events, notes and verdicts as a
text log; a panel per joint with its measured and reference positions and its limits (a revolute joint's in degrees,
a prismatic joint's in metres); the joints' speeds, torques (a prismatic joint's forces) and tracking errors, a panel
per unit; a panel per sensor reading; and a panel per group of the plugins' own series (a series
``patient/cuff_force_n/upper_arm`` lands with the other ``patient/cuff_force_n/*``, ``controller/...`` in the
controller's) — which is how a plugin contributes a panel: by the names of the series it returns.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np
import rerun.blueprint as rrb

# the eye looks at the scene's centre from the front left, above: the view a clinician standing there has
EYE_DIRECTION = np.array([1.0, -1.3, 0.75]) / np.linalg.norm([1.0, -1.3, 0.75])
MIN_RADIUS_M = 0.35  # (a small robot still shows its surroundings)
LEGENDS_UP_TO = 8  # joints whose angle panels still have room for a legend

# units named by a series' last name part, as rehabkit's own names end (metric names follow the same rule)
UNITS = (("_deg_s", "deg/s"), ("_deg", "deg"), ("_nm", "N·m"), ("_n", "N"), ("_mm", "mm"), ("_ms", "ms"),
         ("_m_s2", "m/s²"), ("_m", "m"), ("_s", "s"), ("_rad_s", "rad/s"), ("_rad", "rad"))


def _split_unit(name: str) -> tuple[str, str | None]:
    """A name without its unit suffix, and the unit (``cuff_force_n`` → ``cuff_force``, ``N``)."""
    for suffix, unit in UNITS:
        if name.endswith(suffix):
            return name[: -len(suffix)], unit
    return name, None


def labelled(name: str) -> str:
    """A series' label with its unit: ``cuff_force_n`` → ``cuff force [N]``."""
    base, unit = _split_unit(name)
    text = re.sub(r"_+", " ", base).strip() or name
    return f"{text} [{unit}]" if unit else text


def frame(points: np.ndarray) -> tuple[list[float], list[float]]:
    """An eye position and the point it looks at for a 3-D view that holds ``points`` (world frame, m)."""
    pts = np.asarray(points, float).reshape(-1, 3)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if not len(pts):
        pts = np.zeros((1, 3))
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    centre = (lo + hi) / 2
    radius = max(MIN_RADIUS_M, float(np.linalg.norm(hi - lo)) / 2)
    eye = centre + 2.6 * radius * EYE_DIRECTION
    return [round(float(v), 4) for v in eye], [round(float(v), 4) for v in centre]


@dataclass
class Contents:
    """What a recording holds, gathered as it is written (entity paths in the order they first came)."""

    joints: list[str]
    units: list[str] | None = None  # each joint's unit: deg (revolute) or m (prismatic); None: all deg
    scene_points: list[np.ndarray] = field(default_factory=list)  # world points the 3-D view must hold
    sensors: dict[str, dict[str, bool]] = field(default_factory=dict)  # sensor -> reading key -> is an image
    series: list[str] = field(default_factory=list)  # the plugins' series, by path
    joint_space: bool = False  # a planner's joint-space drawing (a 3-DoF robot's collision map)

    def add_series(self, path: str) -> None:
        if path not in self.series:
            self.series.append(path)

    def add_sensor(self, sensor: str, key: str, image: bool) -> None:
        self.sensors.setdefault(sensor, {}).setdefault(key, image)


def series_groups(paths: list[str]) -> dict[str, list[str]]:
    """Series paths grouped into panels: by their parent path (``a/b/c`` with the other ``a/b/*``), sorted."""
    groups: dict[str, list[str]] = {}
    for path in sorted(paths):
        parent = path.rsplit("/", 1)[0] if "/" in path else path
        groups.setdefault(parent, []).append(path)
    return groups


def blueprint(contents: Contents) -> rrb.Blueprint:
    """The layout for a recording that holds ``contents``."""
    eye, target = frame(np.concatenate([np.reshape(p, (-1, 3)) for p in contents.scene_points])
                        if contents.scene_points else np.zeros((1, 3)))
    scene = rrb.Spatial3DView(name="scene", origin="world", eye_controls=rrb.EyeControls3D(
        kind=rrb.Eye3DKind.Orbital, position=eye, look_target=target, eye_up=[0.0, 0.0, 1.0]))
    left = [scene, rrb.TextLogView(name="events, notes and verdicts", origin="events")]
    # (a humanoid's 29 panels leave no room for legends: the title names the joint, the colours say the rest)
    legend = rrb.PlotLegend(corner=rrb.Corner2D.LeftTop, visible=len(contents.joints) <= LEGENDS_UP_TO)
    units = contents.units or ["deg"] * len(contents.joints)  # (a prismatic joint's panels in metres)
    tabs = [rrb.Grid(*[rrb.TimeSeriesView(name=f"{j} [{u}]", origin=f"joints/{j}", plot_legend=legend)
                       for j, u in zip(contents.joints, units)],
                     name="joint angles" if "m" not in units else "joint positions")]
    shared = []
    if "deg" in units:
        shared += [rrb.TimeSeriesView(name="joint speeds [deg/s]", origin="joint_velocity_deg_s"),
                   rrb.TimeSeriesView(name="joint torques [N·m]", origin="joint_torque_nm"),
                   rrb.TimeSeriesView(name="tracking errors [deg]", origin="tracking_error_deg")]
    if "m" in units:
        shared += [rrb.TimeSeriesView(name="joint speeds [m/s]", origin="joint_velocity_m_s"),
                   rrb.TimeSeriesView(name="joint forces [N]", origin="joint_force_n"),
                   rrb.TimeSeriesView(name="tracking errors [m]", origin="tracking_error_m")]
    efforts = ", ".join(w for w, u in (("torques", "deg"), ("forces", "m")) if u in units)
    tabs.append(rrb.Grid(*shared, name=f"speeds, {efforts}, errors"))
    for top, groups in _by_top(series_groups(contents.series)).items():
        tabs.append(rrb.Grid(*[rrb.TimeSeriesView(name=labelled(parent.split("/")[-1]) if parent != top else top,
                                                  origin=parent, contents=members)
                               for parent, members in groups.items()], name=top))
    if contents.sensors:
        views = []
        for sensor, keys in contents.sensors.items():
            for key, image in keys.items():
                path = f"sensors/{sensor}/{key}"
                views.append(rrb.Spatial2DView(name=f"{sensor}: {key}", origin=path) if image else
                             rrb.TimeSeriesView(name=f"{sensor}: {labelled(key)}", origin=path))
        tabs.append(rrb.Grid(*views, name="sensors"))
    if contents.joint_space:  # (its axes the first joints', each in its own unit)
        axes = units[:3]
        tabs.append(rrb.Spatial3DView(name=f"joint space [{axes[0] if len(set(axes)) == 1 else ', '.join(axes)}]",
                                      origin="joint_space"))
    return rrb.Blueprint(
        rrb.Horizontal(rrb.Vertical(*left, row_shares=[3, 1]), rrb.Tabs(*tabs), column_shares=[1, 1]),
        rrb.BlueprintPanel(state="collapsed"), rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed"), auto_layout=False, auto_views=False)


def _by_top(groups: dict[str, list[str]]) -> dict[str, dict[str, list[str]]]:
    """Panels under a tab per series family (``patient``, ``controller``, ``link``, ...)."""
    out: dict[str, dict[str, list[str]]] = {}
    for parent, members in groups.items():
        out.setdefault(parent.split("/")[0], {})[parent] = members
    return out
