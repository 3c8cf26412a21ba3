"""The human arm models rehabkit straps into a robot: MyoSuite's MyoArm and MyoElbow (package ``myo-sim``).

The models are MuJoCo MJCF of the MyoSuite project (Apache-2.0), loaded from the installed ``myo_sim`` package:
MyoArm — the right upper limb of the MoBL model (Holzbaur et al. 2005), 38 joints, 63 muscles; MyoElbow — the
elbow alone, 1 joint, 6 muscles. rehabkit names the joints a study talks about in one vocabulary
(``shoulder_elevation``, ``elbow_flexion``, …) and groups muscles the way clinicians do (``elbow_flexors``, …).

:class:`HumanArm` is one such arm inside a compiled scene: the addresses of its joints and muscles, the
kinematic coupling of MyoArm's shoulder girdle (joint equalities: scapula and clavicle follow the elevation),
and the muscles' force and moment arms for the static optimisation.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass, field
from importlib.metadata import version
from pathlib import Path

import mujoco
import numpy as np

from rehabkit.numerics.indices import span

PREFIX = "human/"


@dataclass(frozen=True)
class ArmCatalogue:
    """What rehabkit knows of one MyoSuite arm model.

    Attributes:
        spec_name: The model's name in ``myo_sim``.
        joints: rehabkit's joint name → the model's, for the joints the person drives.
        shoulder_body: Its origin is the shoulder (glenohumeral) centre.
        elbow_body: Its origin is on the elbow axis.
        wrist_body: Its origin is the wrist centre (or a site of that name).
        hand_body: The body holding a handle.
        groups: Muscle group → muscle names (the static optimisation uses these muscles).
        side: Which arm it is.
    """

    spec_name: str
    joints: dict[str, str]
    shoulder_body: str
    elbow_body: str
    wrist: str
    hand_body: str
    groups: dict[str, tuple[str, ...]]
    side: str = "right"

    @property
    def muscles(self) -> tuple[str, ...]:
        return tuple(m for group in self.groups.values() for m in group)


MYOARM = ArmCatalogue(
    "myoarm",
    {"shoulder_plane": "elv_angle_r", "shoulder_elevation": "shoulder_elv_r", "shoulder_rotation": "shoulder_rot_r",
     "elbow_flexion": "elbow_flexion_r", "pronation": "pro_sup_r", "wrist_deviation": "deviation_r",
     "wrist_flexion": "flexion_r"},
    "humerus_r", "ulna_r", "lunate_r", "capitate_r",
    {"shoulder": ("DELT1", "DELT2", "DELT3", "SUPSP", "INFSP", "SUBSC", "TMIN", "TMAJ", "PECM1", "PECM2", "PECM3",
                  "LAT1", "LAT2", "LAT3", "CORB"),
     "elbow_flexors": ("BIClong", "BICshort", "BRA", "BRD"),
     "elbow_extensors": ("TRIlong", "TRIlat", "TRImed", "ANC"),
     "forearm": ("SUP", "PT", "PQ"),
     "wrist": ("ECRL", "ECRB", "ECU", "FCR", "FCU", "PL")},
)
MYOELBOW = ArmCatalogue(
    "myoelbow", {"elbow_flexion": "r_elbow_flex"}, "r_humerus", "r_ulna_radius_hand", "wrist",
    "r_ulna_radius_hand",
    {"elbow_flexors": ("BIClong", "BICshort", "BRA"), "elbow_extensors": ("TRIlong", "TRIlat", "TRImed")},
)
CATALOGUE = {"myoarm": MYOARM, "myoelbow": MYOELBOW}
# the arm models' axes: the person looks along -y, their left is +x, z is up
PERSON_FROM_MODEL = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def load_arm_spec(model: str) -> mujoco.MjSpec:
    """The arm's MjSpec from the installed ``myo_sim``, its geoms made touch-free (the straps carry every force
    between the person and the robot; bones meeting the robot's links would be a second, unmodelled contact).

    ``myo_sim`` builds MyoArm from its parts (~0.7 s); the result, made ready for a robot's scene, is kept as MJCF
    under ``$REHABKIT_CACHE``, one file per model, ``myo-sim`` and MuJoCo version and install folder: ~10 ms.
    """
    import myo_sim

    from rehabkit.core.io import atomic_write_text
    from rehabkit.workspace.build import cache_dir

    where = hashlib.sha256(str(Path(myo_sim.__file__).parent).encode()).hexdigest()[:8]
    path = cache_dir() / "myo" / f"{model}-{version('myo-sim')}-mujoco{mujoco.__version__}-{where}-v2.json"
    if path.exists():
        kept = json.loads(path.read_text())
        spec = mujoco.MjSpec.from_string(kept["xml"])
        spec.modelfiledir = kept["modelfiledir"]  # the meshes' paths are relative to the model's own folder
        return spec
    with _quiet_output():  # MyoArm's loader attaches a part without a prefix, and MuJoCo prints a warning of it
        spec = myo_sim.load_spec(CATALOGUE[model].spec_name).copy()  # the copy is whole: it builds quietly
    # MyoSuite's own stage (floor, platform, room), light and cameras stay out of the robot's scene
    for item in [*spec.worldbody.geoms, *spec.lights, *spec.cameras]:
        spec.delete(item)
    for geom in spec.geoms:
        geom.contype, geom.conaffinity = 0, 0
    for key in list(spec.keys):  # a keyframe sized for the arm alone would not fit the composed scene
        spec.delete(key)
    spec.njmax, spec.nconmax, spec.nuser_jnt = -1, -1, -1  # the scene's own sizes apply (MuJoCo warned of each)
    with _quiet_output():
        text = spec.to_xml()
    atomic_write_text(path, json.dumps({"xml": text, "modelfiledir": spec.modelfiledir}))
    return spec


@dataclass
class HumanArm:
    """An arm of :data:`CATALOGUE` compiled into ``model`` under :data:`PREFIX`."""

    catalogue: ArmCatalogue
    model: mujoco.MjModel
    data: mujoco.MjData
    jnt: dict[str, int] = field(init=False)  # rehabkit joint name → joint id
    dofs: np.ndarray = field(init=False)  # every human dof address
    driven: np.ndarray = field(init=False)  # dof addresses of the driven joints, in catalogue order
    muscles: np.ndarray = field(init=False)  # actuator ids of the static optimisation's muscles
    groups: dict[str, np.ndarray] = field(init=False)  # group → indices into ``muscles``

    def __post_init__(self) -> None:
        m, cat = self.model, self.catalogue
        self.jnt = {k: m.joint(PREFIX + v).id for k, v in cat.joints.items()}
        human = [j for j in range(m.njnt) if m.joint(j).name.startswith(PREFIX)]
        self.dofs = np.array([m.jnt_dofadr[j] for j in human])
        self.driven = np.array([m.jnt_dofadr[j] for j in self.jnt.values()])
        self.muscles = np.array([m.actuator(PREFIX + name).id for name in cat.muscles])
        self.muscle_span = span(self.muscles)  # (a slice where contiguous: cheaper in the hot loop)
        index = {name: i for i, name in enumerate(cat.muscles)}
        self.groups = {g: np.array([index[n] for n in names]) for g, names in cat.groups.items()}
        self.all_muscles = np.array([a for a in range(m.nu) if m.actuator(a).name.startswith(PREFIX)])
        self.f0 = m.actuator_gainprm[self.muscles, 2].copy()  # peak isometric force [N]
        lr, rng = m.actuator_lengthrange[self.muscles], m.actuator_gainprm[self.muscles, :2]
        self.l0 = (lr[:, 1] - lr[:, 0]) / (rng[:, 1] - rng[:, 0])  # optimal fibre length [m] (MuJoCo's L0)
        self._coupling = self._joint_couplings()
        self._linear = None
        if all(not np.any(poly[2:]) for _, _, poly, _ in self._coupling):  # MyoArm's are: C is constant
            self._linear = self.coupling_matrix()
        self.body = {k: m.body(PREFIX + getattr(cat, f"{k}_body")).id for k in ("shoulder", "elbow", "hand")}
        self.wrist_site = m.site(PREFIX + cat.wrist).id if _has_site(m, PREFIX + cat.wrist) else None
        self.wrist_body = None if self.wrist_site is not None else m.body(PREFIX + cat.wrist).id

    def _joint_couplings(self) -> list[tuple[int, int, np.ndarray, float]]:
        """MyoArm's shoulder girdle follows the arm by joint equalities, q₁ = q₁⁰ + poly(q₂ − q₂⁰):
        (dependent qpos address, independent qpos address, polynomial, q₂⁰)."""
        m, out = self.model, []
        for e in range(m.neq):
            if m.eq_type[e] != mujoco.mjtEq.mjEQ_JOINT:
                continue
            j1, j2 = m.eq_obj1id[e], m.eq_obj2id[e]
            if j2 < 0 or not m.joint(j1).name.startswith(PREFIX):
                continue
            a1, a2 = m.jnt_qposadr[j1], m.jnt_qposadr[j2]
            out.append((int(a1), int(a2), m.eq_data[e, :5].copy(), float(m.qpos0[a2])))
        return out

    def set_pose(self, qpos: np.ndarray, values: dict[str, float]) -> None:
        """Write the driven joints' ``values`` [rad] into ``qpos`` and the joints that follow them."""
        m = self.model
        for name, v in values.items():
            qpos[m.jnt_qposadr[self.jnt[name]]] = v
        for a1, a2, poly, x0 in self._coupling:
            x = qpos[a2] - x0
            qpos[a1] = m.qpos0[a1] + poly[0] + x * (poly[1] + x * (poly[2] + x * (poly[3] + x * poly[4])))

    def coupling_matrix(self) -> np.ndarray:
        """C (nv × driven): human dof velocities from the driven joints' (the girdle's couplings included), so
        generalised forces on the human reduce to the driven joints as Cᵀ f."""
        if self._linear is not None:
            return self._linear
        m, d = self.model, self.data
        C = np.zeros((m.nv, len(self.driven)))
        C[self.driven, np.arange(len(self.driven))] = 1.0
        col = {int(m.jnt_qposadr[j]): i for i, j in enumerate(self.jnt.values())}
        for a1, a2, poly, x0 in self._coupling:
            if a2 in col:
                x = d.qpos[a2] - x0
                slope = poly[1] + x * (2 * poly[2] + x * (3 * poly[3] + x * 4 * poly[4]))
                C[self._dof_of_qpos(a1), col[a2]] += slope
        return C

    def _dof_of_qpos(self, adr: int) -> int:
        m = self.model
        j = int(np.flatnonzero(m.jnt_qposadr == adr)[0])
        return int(m.jnt_dofadr[j])

    def wrist_position(self) -> np.ndarray:
        d = self.data
        return d.site_xpos[self.wrist_site] if self.wrist_site is not None else d.xpos[self.wrist_body]

    def segment_line(self, segment: str) -> tuple[np.ndarray, np.ndarray]:
        """The segment's axis in the world: (start, end) — shoulder→elbow, elbow→wrist, or the hand's."""
        d = self.data
        shoulder, elbow = d.xpos[self.body["shoulder"]], d.xpos[self.body["elbow"]]
        wrist = self.wrist_position()
        if segment == "upper_arm":
            return shoulder, elbow
        if segment == "forearm":
            return elbow, wrist
        return wrist, d.xpos[self.body["hand"]] + (d.xpos[self.body["hand"]] - wrist)


@contextmanager
def _quiet_output():
    """Hold back what C code prints (stdout and stderr); pass on all but MuJoCo's empty-prefix warning."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    with tempfile.TemporaryFile() as held:
        os.dup2(held.fileno(), 1)
        os.dup2(held.fileno(), 2)
        try:
            yield
        finally:
            for fd, copy in ((1, saved[0]), (2, saved[1])):
                os.dup2(copy, fd)
                os.close(copy)
            held.seek(0)
            text = held.read().decode(errors="replace")
    rest = [line for line in text.splitlines() if line.strip() and "empty prefix" not in line]
    if rest:
        print("\n".join(rest), file=sys.stderr)


def _has_site(m: mujoco.MjModel, name: str) -> bool:
    try:
        m.site(name)
    except KeyError:
        return False
    return True
