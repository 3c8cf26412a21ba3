"""The ARM's keypad HMI with record and replay (after Stuyt et al.), driven by a key timeline.

A scenario lists key presses (time, key, how long it is held). The controller walks
the keypad menus (``arm_keypad_menu``), turns held keys into joint or Cartesian jogs
(ramped, as the ARM limits acceleration), stores targets and timed action sequences in
the user's patch store, and replays them: a target through the scenario's planner
(e.g. ``box-avoid``: around the tray and other obstacles), a sequence by re-issuing
its actions with their timing. Fold and unfold are preprogrammed joint motions. Any
key pressed during an automatic motion stops it. The resulting joint reference is
servoed by PD with gravity compensation.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydantic import Field, ValidationError, model_validator
from pydantic_core import InitErrorDetails, PydanticCustomError
from rehabkit_plugins.controllers.arm_keypad_jog import Jog, Jogger, Quintic
from rehabkit_plugins.controllers.arm_keypad_menu import MENUS, STORE_HOLD_S, check_timeline

from rehabkit import hookimpl
from rehabkit.core.kinds.capabilities import LiftArmGripper
from rehabkit.core.kinds.interfaces import Context, Controller, PlanningError, StrictModel, Target
from rehabkit.core.results.metric import Metric
from rehabkit.store.patches import Action, Patch, open_store

SETTLE_S = 1.0  # after a replay ends, the error to the stored target is measured this much later


class KeyPress(StrictModel):
    """One press of a keypad button."""

    at: float = Field(ge=0, description="[s] from the start")
    key: str
    hold_s: float = Field(0.2, gt=0, description="how long it is held [s] (jog keys move while held)")


class ArmKeypadConfig(StrictModel):
    """Key timeline, patch store, jog speeds, preprogrammed postures and servo gains."""

    keys: list[KeyPress] = Field(description="the user's key presses, in time order")
    store: str = Field("user", description="'user' (the user's data directory), 'run' (a fresh store in the "
                                           "run's output folder) or a path to a patch store file")
    jog_speed_m_s: float = Field(0.05, gt=0, le=0.099, description="Cartesian jog speed (ARM limit 9.9 cm/s)")
    jog_turn_deg_s: float = Field(15.0, gt=0, le=30.0, description="gripper roll/pitch/yaw jog speed")
    jog_joint_fraction: float = Field(0.5, gt=0, le=1.0, description="joint jog speed / joint speed limit")
    ramp_s: float = Field(0.25, gt=0, description="time to reach jog speed and to stop after release")
    fold_deg: list[float] = Field([0.0, -170.0, 150.0, 0.0, 20.0, 0.0], min_length=6, max_length=6,
                                  description="the parked posture beside the wheelchair (six arm joints)")
    unfold_deg: list[float] = Field([20.0, -120.0, 40.0, 0.0, 80.0, 0.0], min_length=6, max_length=6,
                                    description="the home posture in front of the user (six arm joints)")
    # the wrist's small inertia needs lower damping gains for a stable discrete loop at 500 Hz (kd·dt/I < 2)
    kp_arm: list[float] = Field([400.0, 400.0, 400.0, 100.0, 100.0, 100.0], min_length=6, max_length=6,
                                description="joints 1-6 stiffness [N·m/rad]")
    kd_arm: list[float] = Field([40.0, 40.0, 40.0, 5.0, 5.0, 5.0], min_length=6, max_length=6,
                                description="joints 1-6 damping [N·m·s/rad]")
    kp_lift: float = Field(20000.0, ge=0, description="[N/m]")
    kd_lift: float = Field(2000.0, ge=0, description="[N·s/m]")
    kp_gripper: float = Field(400.0, ge=0, description="[N/m]")
    kd_gripper: float = Field(20.0, ge=0, description="[N·s/m]")

    @model_validator(mode="after")
    def _walk_menus(self) -> ArmKeypadConfig:
        problems = check_timeline([(k.at, k.key, k.hold_s) for k in self.keys])
        if problems:  # located at the offending press, so the scenario error points at its line
            raise ValidationError.from_exception_data(type(self).__name__, [
                InitErrorDetails(type=PydanticCustomError("keypad", text), loc=("keys", i, "key"),
                                 input=self.keys[i].key) for i, text in problems])
        return self


@dataclass
class _Auto:
    what: str
    trajectory: object
    t0: float
    patch: int | None = None
    pose: np.ndarray | None = None


@dataclass
class _Stats:
    stored: int = 0
    sequences_stored: int = 0
    replays: int = 0
    sequences_replayed: int = 0
    replay_pos_err: list[float] = field(default_factory=list)
    replay_rot_err: list[float] = field(default_factory=list)
    sequence_err_deg: list[float] = field(default_factory=list)
    failures: int = 0


class ArmKeypad(Controller):
    """ARM keypad HMI: menus, jogs, fold/unfold, record and replay of patches, PD + gravity servo."""

    metrics = (
        Metric("patches_stored", "count", description="patches stored with the keypad"),
        Metric("replays", "count", description="patches replayed"),
        Metric("replay_failures", "count", description="replays the planner could not make"),
        Metric("replay_position_error_m", "m", description="largest hand position error at a replayed patch"),
        Metric("replay_orientation_error_deg", "deg", description="largest hand orientation error at a replayed patch"),
        Metric("sequences_stored", "count", description="action sequences stored"),
        Metric("sequences_replayed", "count", description="action sequences replayed"),
        Metric("sequence_replay_error_deg", "deg", description="largest joint error of a replayed sequence"),
    )

    own_reference = True
    requires = (LiftArmGripper,)

    def __init__(self, config: ArmKeypadConfig, context: Context):
        robot = context.robot
        self.config, self.robot, self.ctx = config, robot, context
        self.model = robot.model
        self.arm, self.lift, self.grip = robot.arm, robot.lift_index, robot.gripper_index
        n = self.model.dof
        self.kp, self.kd = np.zeros(n), np.zeros(n)
        self.kp[self.arm], self.kd[self.arm] = config.kp_arm, config.kd_arm
        self.kp[self.grip], self.kd[self.grip] = config.kp_gripper, config.kd_gripper
        if self.lift is not None:
            self.kp[self.lift], self.kd[self.lift] = config.kp_lift, config.kd_lift
        self.store = open_store(config.store, context.out_dir, context.resolve, dry=context.dry_run)
        self.jogger = Jogger(robot, config)
        self.keys = sorted(config.keys, key=lambda k: k.at)
        self.menu, self.selected = "MAIN", None
        self.jog: Jog | None = None
        self.auto: _Auto | None = None
        self.store_at: float | None = None
        self.recording: list[Action] | None = None
        self.record_start_q: np.ndarray | None = None
        self.last_action_end: float | None = None
        self.replay_queue: list[tuple[float, str, float]] = []
        self.sequence_check: tuple[float, np.ndarray, np.ndarray] | None = None
        self.pending_check: tuple[float, np.ndarray] | None = None
        self.stats = _Stats()
        self.q_ref: np.ndarray | None = None
        self.qd_ref = np.zeros(n)
        self.joint_reference = None

    def _note(self, t: float, text: str) -> None:
        if self.ctx.note is not None:
            self.ctx.note(t, f"keypad: {text}")

    # -- keys -------------------------------------------------------------------

    def _press(self, t: float, key: str, hold: float, q: np.ndarray, qd: np.ndarray) -> None:
        if self.auto is not None or self.replay_queue:
            self._note(t, f"'{key}' stops the {self.auto.what if self.auto else 'sequence replay'}")
            self.auto, self.replay_queue, self.jog = None, [], None
            self.q_ref, self.qd_ref = q.copy(), np.zeros_like(self.qd_ref)
        action = MENUS[self.menu][key]
        if action.startswith("go:"):
            self.menu = action[3:]
            self._note(t, f"{self.menu} menu")
        elif action == "jog":
            self._start_jog(t, key, t + hold)
            if self.recording is not None:
                if self.last_action_end is not None and t > self.last_action_end:
                    self.recording.append(Action(command="wait", duration_s=round(t - self.last_action_end, 6)))
                self.recording.append(Action(command=key, duration_s=hold))
                self.last_action_end = t + hold
        elif action == "select":
            self.selected = int(key)
            self._note(t, f"patch {key} selected")
        elif action == "store":
            self.store_at = t + STORE_HOLD_S
        elif action == "record-start":
            self.recording, self.record_start_q, self.last_action_end = [], q.copy(), None
            self._note(t, f"recording a sequence for patch {self.selected}")
        elif action == "record-stop":
            self._stop_recording(t, q)
        elif action in ("fold", "unfold"):
            self._posture(t, action)
        elif action == "play":
            self._play(t, int(key), q, qd)

    def _start_jog(self, t: float, key: str, release_at: float) -> None:
        self.jog = self.jogger.start(key, release_at, self.q_ref)

    def _stop_recording(self, t: float, q: np.ndarray) -> None:
        actions = [a for a in self.recording if a.command != "wait" or a.duration_s > 0]
        if not any(a.command != "wait" for a in actions):
            self._note(t, "nothing recorded: no action between 'circle' and 'square'")
        else:
            self.store.save(self.selected, Patch(kind="sequence", robot=self.model.name, actions=actions,
                                                 net_motion_rad=(q - self.record_start_q).tolist()))
            self.stats.sequences_stored += 1
            self._note(t, f"patch {self.selected}: sequence of {sum(a.command != 'wait' for a in actions)} "
                          "actions stored")
        self.recording = None

    def _store_target(self, t: float, q: np.ndarray) -> None:
        pose = self.robot.fk(q)
        self.store.save(self.selected, Patch(kind="target", robot=self.model.name, joints_rad=q.tolist(),
                                             pose=pose.tolist()))
        self.stats.stored += 1
        self._note(t, f"patch {self.selected}: target stored at {np.round(pose[:3, 3], 3).tolist()} m (base frame)")

    def _posture(self, t: float, which: str) -> None:
        goal = self.q_ref.copy()
        goal[self.arm] = np.radians(self.config.fold_deg if which == "fold" else self.config.unfold_deg)
        v = self.model.limits.velocity * 0.8
        duration = float(np.max(1.875 * np.abs(goal - self.q_ref) / v))
        self.auto = _Auto(which, Quintic(self.q_ref.copy(), goal, duration), t)
        self._note(t, f"{which}: {duration:.1f} s")

    def _play(self, t: float, slot: int, q: np.ndarray, qd: np.ndarray) -> None:
        patch = self.store.load(slot)
        if patch is None:
            self._note(t, f"patch {slot} is empty")
            return
        if patch.robot != self.model.name:
            self._note(t, f"patch {slot} was recorded on robot '{patch.robot}', not '{self.model.name}'")
            return
        if patch.kind == "sequence":
            at = t
            for a in patch.actions:
                if a.command != "wait":
                    self.replay_queue.append((at, a.command, a.duration_s))
                at += a.duration_s
            if patch.net_motion_rad is not None and len(patch.net_motion_rad) == self.model.dof:
                self.sequence_check = (at + self.config.ramp_s + SETTLE_S, q.copy(), np.asarray(patch.net_motion_rad))
            self.stats.sequences_replayed += 1
            self._note(t, f"play patch {slot}: sequence of {len(self.replay_queue)} actions")
            return
        goal_q = np.asarray(patch.joints_rad)
        if len(goal_q) != self.model.dof:
            self._note(t, f"patch {slot} holds {len(goal_q)} joints; this arm has {self.model.dof}")
            return
        target = Target(f"patch {slot}", q=goal_q, pose=np.asarray(patch.pose))
        try:
            plan = self.ctx.plan(t, q, qd, [target])
        except PlanningError as exc:
            self.stats.failures += 1
            self._note(t, f"play patch {slot}: no path ({exc})")
            return
        self.auto = _Auto(f"replay of patch {slot}", plan.trajectory, t, slot, target.pose)
        self.stats.replays += 1
        length = plan.details.get("path_length_m")
        self._note(t, f"play patch {slot}: {plan.trajectory.duration:.1f} s"
                      + (f", path {length:.3f} m" if length is not None else ""))

    # -- reference --------------------------------------------------------------

    def _advance_auto(self, t: float, q: np.ndarray) -> None:
        auto = self.auto
        x, xd, _ = auto.trajectory.sample(np.array([t - auto.t0]))
        self.q_ref, self.qd_ref = x[0], xd[0]
        if t - auto.t0 >= auto.trajectory.duration:
            if auto.patch is not None:
                self.pending_check = (t + SETTLE_S, auto.pose)
            self.auto = None
            self.qd_ref = np.zeros_like(self.qd_ref)

    def _checks(self, t: float, q: np.ndarray) -> None:
        if self.pending_check is not None and t >= self.pending_check[0]:
            reached = self.robot.fk(q)
            goal = self.pending_check[1]
            self.stats.replay_pos_err.append(float(np.linalg.norm(reached[:3, 3] - goal[:3, 3])))
            cos = (np.trace(reached[:3, :3].T @ goal[:3, :3]) - 1) / 2
            self.stats.replay_rot_err.append(float(np.degrees(np.arccos(np.clip(cos, -1, 1)))))
            self.pending_check = None
        if self.sequence_check is not None and t >= self.sequence_check[0]:
            _, q_start, recorded = self.sequence_check
            moved = (q - q_start)[self.arm] - recorded[self.arm]
            self.stats.sequence_err_deg.append(float(np.degrees(np.abs(moved)).max()))
            self.sequence_check = None
        if self.store_at is not None and t >= self.store_at:
            self._store_target(t, q)
            self.store_at = None

    def compute(self, t, q, qd, q_ref, qd_ref, qdd_ref):
        dt = self.ctx.control_dt
        if self.q_ref is None:
            self.q_ref = q.copy()
        while self.keys and self.keys[0].at <= t + 1e-9:
            k = self.keys.pop(0)
            self._press(t, k.key, k.hold_s, q, qd)
        while self.replay_queue and self.replay_queue[0][0] <= t + 1e-9:
            _, key, hold = self.replay_queue.pop(0)
            self._start_jog(t, key, t + hold)
        if self.auto is not None:
            self._advance_auto(t, q)
        elif self.jog is not None:
            new = self.jogger.advance(self.jog, t, dt, self.q_ref)
            if new is self.q_ref:
                self._note(t, f"'{self.jog.key}': the arm can go no further (reach, joint limit or singularity)")
            if new is None or new is self.q_ref:
                self.jog, self.qd_ref = None, np.zeros_like(self.qd_ref)
            else:
                self.qd_ref, self.q_ref = (new - self.q_ref) / dt, new
        self._checks(t, q)
        self.joint_reference = self.q_ref
        return self.kp * (self.q_ref - q) + self.kd * (self.qd_ref - qd) + self.robot.gravity_torque(q)

    def run_metrics(self, trace) -> dict[str, float]:
        s = self.stats
        out = {"patches_stored": float(s.stored), "sequences_stored": float(s.sequences_stored),
               "replays": float(s.replays), "sequences_replayed": float(s.sequences_replayed),
               "replay_failures": float(s.failures)}
        if s.replay_pos_err:
            out["replay_position_error_m"] = max(s.replay_pos_err)
            out["replay_orientation_error_deg"] = max(s.replay_rot_err)
        if s.sequence_err_deg:
            out["sequence_replay_error_deg"] = max(s.sequence_err_deg)
        return out


@hookimpl
def rehabkit_register_controllers(registry) -> None:
    registry.add("arm-keypad", config=ArmKeypadConfig, factory=ArmKeypad)
