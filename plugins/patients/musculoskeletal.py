"""A musculoskeletal patient: MyoSuite's MyoArm or MyoElbow in the robot's scene, strapped to it, driven by
muscles (``myo-sim``, Apache-2.0; see :mod:`rehabkit.musculo.human`).

Each control period the person's intent becomes joint torques — holding their own arm up (``own_weight``) and a
hand force toward the movement's goal as they perceive it (late, noisy, capped, as the spring-damper patient's) —
plus the impairments acting through the drive (tremor, the flexor synergy); static optimisation turns that into
muscle activations (:mod:`rehabkit.musculo.static_opt`), the stretch reflex adds its excitation, and MuJoCo's
activation dynamics and muscle model do the rest. Weakness and fatigue scale the muscles' force, contracture
narrows the joints' passive range. The straps' constraint forces are the interaction force: the safety envelope
checks the largest, the outcome measures report them.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
from rehabkit_plugins.patients.musculoskeletal_settings import MusculoskeletalConfig, per_group, wearable_for

from rehabkit.musculoskeletal import (
    CATALOGUE,
    PREFIX,
    HumanArm,
    MuscleFatigue,
    NoiseStream,
    StaticOptimisation,
    StretchReflex,
    Tremor,
    compose,
    fit_arm,
    load_arm_spec,
    scale_arm,
    span,
    strap_rows,
    strap_solref,
)
from rehabkit.plugin import Context, Drawing, EmbodiedPatient, Metric, SettingError, hookimpl

SERIES_EVERY = 10  # control steps between logged samples
CUFF_ARROW_M_PER_N = 0.01  # the cuff forces drawn 1 cm per N: a 25 N push is a 25 cm arrow


class Musculoskeletal(EmbodiedPatient):
    """A muscle-driven arm (MyoSuite's MyoArm or MyoElbow) in the scene, strapped to the robot; see the module."""

    relaxed = {"drive": {"participation": 0.0}}  # (still holding their own arm up: the robot carries itself only)
    # what its parts change while a run goes (a session snapshot takes them): the noise, the solver's warm start, the
    # reflex's and the tremor's filters, the fatigue (the arm's body is the scene's, taken with the backend's state)
    RUN_STATE_NESTED = ("noise_stream", "so", "reflex", "tremor", "fatigue", "arm")

    metrics = (
        Metric("peak_cuff_force_n", "N", outcome=True, description="largest strap force over the run"),
        Metric("mean_cuff_force_n", "N", outcome=True, description="the largest strap's force, averaged over time"),
        Metric("muscle_effort", outcome=True, description="Σ activation², averaged over time"),
        Metric("drive_saturated_fraction", description="share of steps the muscles could not give the torque asked"),
        Metric("fit_offset_mm", "mm", description="largest strap-to-segment distance the fit left"),
        Metric("muscle_capacity_min", description="the most fatigued muscle's remaining capacity at the end"),
        Metric("arm_scale_upper_arm", description="the model's upper arm stretched by this to the profile's"),
        Metric("arm_scale_forearm", description="the model's forearm bones stretched by this to the profile's"),
    )

    def __init__(self, config: MusculoskeletalConfig, context: Context):
        self.config, self.robot, self.dt = config, context.robot, context.control_dt
        self.cat = CATALOGUE[config.model]
        profile = context.patient
        self.wearable = wearable_for(config, self.cat, self.robot.model, profile)
        n = len(self.cat.muscles)
        self.strength = per_group(config.weakness, self.cat.groups, n, "weakness", 1.0)
        self.reflex_gain = per_group(config.spasticity.gain, self.cat.groups, n, "spasticity.gain", 0.0)
        self.spec = load_arm_spec(config.model)
        for name, (lo, hi) in config.contracture_deg.items():
            joint = self.spec.joint(self.cat.joints[name])
            full = np.degrees(joint.range)
            if not full[0] <= lo < hi <= full[1]:
                raise SettingError(("contracture_deg", name), f"[{lo:g}, {hi:g}] must be an interval inside the "
                                   f"joint's range [{full[0]:.0f}, {full[1]:.0f}]")
            joint.range = np.radians([lo, hi])
        self.scale: dict[str, float] = {}  # the segments' stretch
        segments = {k: v for k, v in (profile.segments if profile is not None else {}).items()
                    if k in ("upper_arm", "forearm")}
        if config.scale_to_profile and segments:
            self.scale = scale_arm(self.spec, self.cat, segments, memo=config.model)
        self.delay_s = config.drive.delay_s
        self.cartesian = context.reference_space == "cartesian"
        self.noise_stream = NoiseStream(context.stream("patient"))
        self.arm: HumanArm | None = None
        self._goal_key, self._goal_world_at = b"", np.zeros(3)

    # -- the scene ------------------------------------------------------------------------------------

    def compose(self, spec) -> None:
        bodies = {"upper_arm": self.cat.shoulder_body, "hand": self.cat.hand_body,
                  "forearm": "radius_r" if self.config.model == "myoarm" else self.cat.elbow_body}
        compose(spec, self.spec, self.wearable, self.robot.model.base_pose, self.wearable.straps,
                {k: PREFIX + v for k, v in bodies.items()})

    def bind(self, model, data) -> None:
        self.m, self.d = model, data
        arm = self.arm = HumanArm(self.cat, model, data)
        self.so = StaticOptimisation(arm)
        self.eqs = [model.equality(f"{PREFIX}strap_{s.segment}").id for s in self.wearable.straps]
        self.robot_dofs = span(np.array([model.jnt_dofadr[model.joint(j).id] for j in self.robot.model.joint_names]))
        self._full = np.zeros(model.nv)
        self.f0 = arm.f0 * self.strength  # weakness: the active force, passive tissue unchanged
        model.actuator_gainprm[arm.muscles, 2] = self.f0
        cfg = self.config
        self.reflex = StretchReflex(self.reflex_gain, np.full(len(arm.muscles), cfg.spasticity.threshold_l0_s),
                                    cfg.spasticity.reflex_delay_s, arm.l0, self.dt)
        amp = np.array([cfg.tremor.amplitude_nm.get(j, 0.0) for j in self.cat.joints])
        self.tremor = Tremor(amp, cfg.tremor.frequency_hz, cfg.tremor.bandwidth_hz, self.dt, self.noise_stream)
        self.fatigue = MuscleFatigue(len(arm.muscles), cfg.fatigue.rate_per_s, cfg.fatigue.recovery_per_s, self.dt)
        self.noise_a = math.exp(-2 * math.pi * cfg.drive.noise_hz * self.dt)
        self.noise = np.zeros(len(arm.driven))
        self.ee = model.site(self.robot.model.ee_site).id
        self.jac = np.zeros((3, model.nv))
        self.elv = list(self.cat.joints).index("shoulder_elevation") if "shoulder_elevation" in self.cat.joints \
            else None
        self.elbow = list(self.cat.joints).index("elbow_flexion")
        self._reset_record()

    def _reset_record(self) -> None:
        self.peak = self.force_sum = self.effort_sum = 0.0
        self.steps = self.saturated = 0
        self.force = np.zeros(3)
        self._worst = 0  # the strap pressing hardest at the last step
        self._t: list[float] = []
        self._rows: list[np.ndarray] = []

    def place(self) -> None:
        m, d = self.m, self.d
        self.fitted, self.offset = fit_arm(self.arm, self.wearable, self.robot.model.base_pose,
                                           self.wearable.straps, self.eqs)
        d.qvel[self.arm.dofs] = 0.0
        d.act[:] = 0.0
        mujoco.mj_forward(m, d)
        for eq in self.eqs:
            m.eq_solref[eq] = strap_solref(d, eq, self.config.straps.stiffness_n_m, self.config.straps.damping_ns_m)
        # the person was holding their arm before the run began: their muscles start at that activation
        hold = self.config.drive.own_weight * (self.arm.coupling_matrix().T @ d.qfrc_bias)
        steady = self.so.solve(self._synergy(hold))
        d.act[self.so.act_of_muscles] = d.ctrl[self.arm.muscles] = steady.activation
        mujoco.mj_forward(m, d)
        hand = self.arm.body["hand"]  # the point of the hand at the robot's handle: where the person aims
        self.hand_body = hand
        self.hand_point = d.xmat[hand].reshape(3, 3).T @ (d.site_xpos[self.ee] - d.xpos[hand])
        self._reset_record()

    # -- each control period --------------------------------------------------------------------------

    def _hand(self) -> tuple[np.ndarray, np.ndarray]:
        d, hand = self.d, self.hand_body
        point = d.xpos[hand] + d.xmat[hand].reshape(3, 3) @ self.hand_point
        mujoco.mj_jac(self.m, d, self.jac, None, point, hand)
        return point, self.jac

    def _goal_world(self, goal: np.ndarray) -> np.ndarray:
        key = goal.tobytes()
        if key != self._goal_key:  # the goal of a reach holds for the whole reach: its hand position is kept
            base = self.robot.model.base_pose
            p = goal if self.cartesian else self.robot.fk(goal)[:3, 3]
            self._goal_key, self._goal_world_at = key, base[:3, :3] @ p + base[:3, 3]
        return self._goal_world_at

    def intent(self, goal: np.ndarray) -> np.ndarray:
        """Torques the person wants at the driven joints: hold the arm, reach for the goal, the synergy."""
        cfg, arm, d = self.config.drive, self.arm, self.d
        C = arm.coupling_matrix()
        tau = cfg.own_weight * (C.T @ d.qfrc_bias)
        if cfg.participation > 0 and goal is not None:
            x, J = self._hand()
            force = cfg.stiffness_n_m * (self._goal_world(goal) - x) - cfg.damping_ns_m * (J @ d.qvel)
            size = float(np.linalg.norm(force))
            if size > cfg.hand_force_n:
                force *= cfg.hand_force_n / size
            reach = C.T @ (J.T @ force)
            self.noise = self.noise_a * self.noise + math.sqrt(1 - self.noise_a**2) * self.noise_stream.normal(
                len(self.noise))
            tau += cfg.participation * reach * (1.0 + cfg.noise * self.noise)
        if self.tremor.active:
            tau += self.tremor.torque()
        return self._synergy(tau)

    def _synergy(self, tau: np.ndarray) -> np.ndarray:
        """The flexor synergy: shoulder elevation effort flexes the elbow with it."""
        if self.elv is not None and self.config.synergy.elbow_per_shoulder > 0:
            tau[self.elbow] += self.config.synergy.elbow_per_shoulder * max(0.0, tau[self.elv])
        return tau

    def excite(self, tau: np.ndarray) -> np.ndarray:
        """Muscle excitations for ``tau`` at the driven joints (static optimisation + stretch reflex), set on the
        scene; returns them."""
        arm, d = self.arm, self.d
        if np.any(tau):
            solution = self.so.solve(tau)
            excitation = solution.activation
        else:  # no intent at all: relaxed (the passive tissue is not fought)
            solution, excitation = None, np.zeros(len(arm.muscles))
        if self.reflex.active:
            excitation = np.minimum(1.0, excitation + self.reflex.excitation(d.actuator_velocity[arm.muscle_span]))
        d.ctrl[arm.muscle_span] = excitation
        if self.fatigue.active:
            self.m.actuator_gainprm[arm.muscle_span, 2] = self.f0 * self.fatigue.step(d.act[self.so.act_of_muscles])
        self.saturated += solution is not None and solution.saturated
        self.effort_sum += float(excitation @ excitation)
        return excitation

    def _strap_rows(self) -> list[slice]:
        return [strap_rows(self.d, eq) for eq in self.eqs]

    def strap_forces(self, rows: list[slice] | None = None) -> list[np.ndarray]:
        """Each strap's force on the robot now, world frame [N]."""
        force = self.d.efc_force
        return [force[r].copy() for r in rows or self._strap_rows()]

    def strap_torque(self, rows: list[slice] | None = None) -> np.ndarray:
        """The straps' torque on the robot's joints now [N·m]: Jᵀ f over their constraint rows."""
        d = self.d
        vec = np.zeros(d.nefc)
        for r in rows or self._strap_rows():
            vec[r] = d.efc_force[r]
        mujoco.mj_mulJacTVec(self.m, d, self._full, vec)
        return self._full[self.robot_dofs].copy()

    def torque(self, t, q, qd, goal):
        excitation = self.excite(self.intent(goal))
        rows = self._strap_rows()
        forces = self.strap_forces(rows)
        sizes = [math.sqrt(float(f @ f)) for f in forces]
        worst = self._worst = int(np.argmax(sizes))
        self.force = forces[worst]
        self.peak = max(self.peak, sizes[worst])
        self.force_sum += sizes[worst]
        if self.steps % SERIES_EVERY == 0:
            self._t.append(t)
            groups = [float(np.mean(excitation[idx])) for idx in self.arm.groups.values()]
            self._rows.append(np.array([*sizes, *groups, float(np.min(self.fatigue.capacity))]))
        self.steps += 1
        return self.strap_torque(rows)

    def interaction_force(self) -> np.ndarray:
        return self.force

    def interaction_torque(self) -> np.ndarray:
        return self.strap_torque()

    def joint_torque(self, q: np.ndarray, force: np.ndarray) -> np.ndarray:
        """Jᵀ F at the point of the robot where the strap pressing hardest is fastened (MuJoCo's Jacobian of the
        scene as it stands: ``q`` is the robot's posture in it)."""
        m, d = self.m, self.d
        eq = self.eqs[self._worst]
        body = m.eq_obj1id[eq]
        point = d.xpos[body] + d.xmat[body].reshape(3, 3) @ m.eq_data[eq, :3]
        jacp = np.zeros((3, m.nv))
        mujoco.mj_jac(m, d, jacp, None, point, body)
        return jacp[:, self.robot_dofs].T @ np.asarray(force, float)

    def state(self) -> np.ndarray:
        """Each muscle group's mean activation and its least fatigued-away capacity (groups in catalogue order)."""
        act = self.d.act[self.so.act_of_muscles]
        cap = self.fatigue.capacity
        return np.array([v for idx in self.arm.groups.values() for v in (act[idx].mean(), cap[idx].min())])

    def drawing(self) -> dict[str, Drawing]:
        """Each muscle's path coloured by its activation (blue at rest, red at full), each strap's force as an
        arrow from the strap, 1 cm per N, labelled with its size; both at the log rate, as the bones."""
        m, d = self.m, self.d
        origins = np.array([d.xpos[m.eq_obj1id[eq]] + d.xmat[m.eq_obj1id[eq]].reshape(3, 3) @ m.eq_data[eq, :3]
                            for eq in self.eqs])
        forces = -np.array(self.strap_forces())  # the force on the person
        labels = [f"{s.segment} {np.linalg.norm(f):.1f} N (1 cm per N)" for s, f in zip(self.wearable.straps, forces)]
        drawn = {"cuffs": Drawing(origins=origins, vectors=forces * CUFF_ARROW_M_PER_N,
                                  arrow_rgba=np.tile([1.0, 0.8, 0.1, 1.0], (len(self.eqs), 1)), arrow_labels=labels)}
        tendons = m.actuator_trnid[self.arm.all_muscles, 0]  # (MuJoCo keeps the paths in tendon order)
        start, count = d.ten_wrapadr[tendons], d.ten_wrapnum[tendons]
        points = d.wrap_xpos.reshape(-1, 3)[start[0] : start[-1] + count[-1]].copy()  # (kept until sent)
        lines = np.split(points, start[1:] - start[0])
        act = d.act[m.actuator_actadr[self.arm.all_muscles]]
        rgba = np.column_stack([0.2 + 0.8 * act, 0.3 * (1 - act), 1.0 - act, np.ones_like(act)])
        return {**drawn, "muscles": Drawing(lines=lines, line_rgba=rgba)}

    # -- the record -----------------------------------------------------------------------------------

    def run_metrics(self, trace) -> dict[str, float]:
        n = max(1, self.steps)
        return {"peak_cuff_force_n": self.peak, "mean_cuff_force_n": self.force_sum / n,
                "muscle_effort": self.effort_sum / n, "drive_saturated_fraction": self.saturated / n,
                "fit_offset_mm": 1000.0 * getattr(self, "offset", 0.0),
                "muscle_capacity_min": float(np.min(self.fatigue.capacity)) if self.arm else 1.0,
                "arm_scale_upper_arm": self.scale.get("upper_arm", 1.0),
                "arm_scale_forearm": self.scale.get("forearm", 1.0)}

    def inputs(self) -> dict[str, str]:
        return {"patient_noise": self.noise_stream.digest.hexdigest()[:16]}

    def series(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        if not self._rows:
            return {}
        t, v = np.asarray(self._t), np.asarray(self._rows)
        out = {f"patient/cuff_force_n/{s.segment}": (t, v[:, i]) for i, s in enumerate(self.wearable.straps)}
        k = len(self.wearable.straps)
        out.update({f"patient/activation/{g}": (t, v[:, k + i]) for i, g in enumerate(self.arm.groups)})
        out["patient/muscle_capacity_min"] = (t, v[:, -1])
        return out


@hookimpl
def rehabkit_register_patients(registry) -> None:
    registry.add("musculoskeletal", config=MusculoskeletalConfig, factory=Musculoskeletal)
