"""Everything a plugin or an extension imports from rehabkit, in one module.

A third-party package imports from here only (``from rehabkit.plugin import Planner, Plan, hookimpl``);
what is not listed in ``__all__`` is internal and may change. The plugin kinds and what each
returns are described in :mod:`rehabkit.core.plugins.hookspecs`; the run-lifecycle hooks an extension
implements in :mod:`rehabkit.core.plugins.lifecycle`.
"""

from rehabkit.core.io import load_yaml
from rehabkit.core.kinds.backend import Drawing, EStopLatchedError
from rehabkit.core.kinds.capabilities import (
    BaseState,
    Cameras,
    Contacts,
    ExternalTorques,
    FloatingBase,
    HeldObjects,
    HostsBodies,
    Instruments,
    NamedJoints,
    PassiveJoints,
    RandomReach,
    SceneGeometry,
    SceneObjects,
    WorkspaceTable,
)
from rehabkit.core.kinds.interfaces import (
    Backend,
    BackendFaultError,
    BodyPoses,
    Contact,
    Context,
    Controller,
    ControllerReference,
    EmbodiedPatient,
    GeomVisual,
    IKUnavailableError,
    Instrument,
    InteractionForceSensor,
    JointRom,
    Patient,
    Plan,
    Planner,
    PlanningError,
    PlanRequest,
    Reading,
    ReferenceSpace,
    Robot,
    Sensor,
    SensorConfig,
    SettingError,
    StrictModel,
    Target,
    Trajectory,
)
from rehabkit.core.kinds.metric import Metric
from rehabkit.core.kinds.names import nearest, suggest
from rehabkit.core.kinds.trace import Trace
from rehabkit.core.plugins.hookspecs import hookimpl
from rehabkit.core.plugins.lifecycle import Contribution, RunTap, Section
from rehabkit.core.plugins.types import Declared
from rehabkit.core.safety.limit_breach import LimitBreach
from rehabkit.core.setup.errors import SetupError
from rehabkit.core.setup.limits import Narrowing
from rehabkit.core.setup.targets import JointWaypoints, angle_axis, angular_distance, joint_waypoints, unreachable
from rehabkit.models.dh import PoseSpec
from rehabkit.models.robot_model import JointLimits, RobotModel
from rehabkit.models.strict import FilePath, SensorName
from rehabkit.models.wearable import Strap, Wearable

# The modules a plugin imports from rehabkit, built-in or third-party: this one and the public helper modules (each
# with its own ``__all__``; see the README's "Public helper modules"). Everything else is internal and may change;
# a plugin never imports a backend (rehabkit.sim, .hardware, .canopen) nor a layer (rehabkit.rehab, .ros, .sweep, ...).
PUBLIC_MODULES = (
    "rehabkit.plugin",
    "rehabkit.kinematics",  # kinematic chains, DH descriptions, the robot model, MJCF building, wearables, robot files
    "rehabkit.trajectories",  # time laws, rest-to-rest timing
    "rehabkit.workspaces",  # voxel workspaces and the searches over them
    "rehabkit.planning",  # joint-space and Cartesian planning helpers, throwing
    "rehabkit.control",  # QP task stack, small solves, learned policies, saved poses
    "rehabkit.sensing",  # Kalman filtering, rigid-body estimation
    "rehabkit.musculoskeletal",  # musculoskeletal arms, their fitting, static optimisation, impairments
    "rehabkit.recordings",  # sessions recorded in ROS bags
)

__all__ = [
    # registering; the modules a plugin may import
    "hookimpl", "Declared", "PUBLIC_MODULES",
    # the plugin kinds and what they exchange
    "Robot", "RobotModel", "JointLimits", "PoseSpec", "Planner", "Plan", "PlanRequest", "Trajectory", "Target",
    "ReferenceSpace", "Controller", "ControllerReference", "Sensor", "SensorConfig", "Instrument",
    "InteractionForceSensor", "Backend", "BodyPoses", "Contact", "GeomVisual", "Patient", "EmbodiedPatient", "JointRom",
    "Context", "StrictModel", "FilePath", "SensorName", "Reading", "Wearable", "Strap",
    # what every kind's run_metrics(trace) reads: the run's record at the control rate
    "Trace",
    # what a plugin draws in the recording
    "Drawing",
    # joint values for a plan's targets (IK where Cartesian, nearest branch, limits checked), and their geometry
    "joint_waypoints", "JointWaypoints", "angular_distance", "angle_axis", "unreachable",
    # what a robot declares it can do, and a plugin ``requires``
    "WorkspaceTable", "RandomReach", "PassiveJoints", "FloatingBase",
    # what a backend declares it can do, and a plugin ``requires``
    "ExternalTorques", "Contacts", "HostsBodies", "SceneGeometry", "SceneObjects", "HeldObjects", "Cameras",
    "Instruments", "BaseState", "NamedJoints",
    # a plugin's own data files and messages: YAML with located errors, "did you mean" for a misspelt name (said
    # after a message, or as an error's fix: SettingError(..., fix=nearest(name, names)))
    "load_yaml", "suggest", "nearest",
    # describing metrics; extensions' contributions and limits
    "Metric", "Contribution", "RunTap", "Section", "Narrowing", "LimitBreach",
    # errors
    "PlanningError", "SettingError", "IKUnavailableError", "BackendFaultError", "EStopLatchedError", "SetupError",
]
