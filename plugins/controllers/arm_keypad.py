"""The ARM's keypad HMI with record and replay (after Stuyt et al.), driven by a key timeline.

A scenario lists key presses (time, key, how long it is held; :mod:`arm_keypad_settings`). The controller walks
the keypad menus (``arm_keypad_menu``), turns held keys into joint or Cartesian jogs (ramped, as the ARM limits
acceleration; ``arm_keypad_jog``), stores targets and timed action sequences in the user's patch store and replays
them (``arm_keypad_patches``): a target through the scenario's planner (e.g. ``box-avoid``: around the tray and
other obstacles), a sequence by re-issuing its actions with their timing. Fold and unfold are preprogrammed joint
motions. Any key pressed during an automatic motion stops it. The resulting joint reference is servoed by PD with
gravity compensation.
"""

from __future__ import annotations

import numpy as np
from rehabkit_plugins.controllers.arm_keypad_jog import Jog, Jogger, Quintic
from rehabkit_plugins.controllers.arm_keypad_menu import MENUS, STORE_HOLD_S
from rehabkit_plugins.controllers.arm_keypad_patches import Auto, PatchBook
from rehabkit_plugins.controllers.arm_keypad_settings import ArmKeypadConfig
from rehabkit_plugins.robots.contracts import LiftArmGripper

from rehabkit.control import open_store
from rehabkit.plugin import Context, Controller, Metric, hookimpl
from rehabkit.trajectories import PEAK_VELOCITY


class ArmKeypad(Controller):
    """ARM keypad HMI: menus, jogs, fold/unfold, record and replay of patches, PD + gravity servo."""

    RUN_STATE_NESTED = ("patches", "jogger", "jog", "auto")  # (its parts changed in place: a snapshot takes them)

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

    reference = "own"
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
        store = open_store(config.store, context.out_dir, context.resolve, dry=context.dry_run)
        self.patches = PatchBook(store, robot, self.arm, config.ramp_s, self._note)
        self.jogger = Jogger(robot, config)
        self.keys = sorted(config.keys, key=lambda k: k.at)
        self.menu, self.selected = "MAIN", None
        self.jog: Jog | None = None
        self.auto: Auto | None = None
        self.q_ref: np.ndarray | None = None
        self.qd_ref = np.zeros(n)
        self.joint_reference = None

    def _note(self, t: float, text: str) -> None:
        if self.ctx.note is not None:
            self.ctx.note(t, f"keypad: {text}")

    # -- keys: the menus' state machine -----------------------------------------------------------------

    def _press(self, t: float, key: str, hold: float, q: np.ndarray, qd: np.ndarray) -> None:
        book = self.patches
        if self.auto is not None or book.replay_queue:
            self._note(t, f"'{key}' stops the {self.auto.what if self.auto else 'sequence replay'}")
            self.auto, book.replay_queue, self.jog = None, [], None
            self.q_ref, self.qd_ref = q.copy(), np.zeros_like(self.qd_ref)
        action = MENUS[self.menu][key]
        if action.startswith("go:"):
            self.menu = action[3:]
            self._note(t, f"{self.menu} menu")
        elif action == "jog":
            self.jog = self.jogger.start(key, t + hold, self.q_ref)
            book.record_jog(t, key, hold)
        elif action == "select":
            self.selected = int(key)
            self._note(t, f"patch {key} selected")
        elif action == "store":
            book.store_at = t + STORE_HOLD_S
        elif action == "record-start":
            book.start_recording(t, q, self.selected)
        elif action == "record-stop":
            book.stop_recording(t, q, self.selected)
        elif action in ("fold", "unfold"):
            self._posture(t, action)
        elif action == "play":
            self.auto = book.play(t, int(key), q, qd, self.ctx.plan) or self.auto

    def _posture(self, t: float, which: str) -> None:
        goal = self.q_ref.copy()
        goal[self.arm] = np.radians(self.config.fold_deg if which == "fold" else self.config.unfold_deg)
        v = self.model.limits.velocity * 0.8
        duration = float(np.max(PEAK_VELOCITY * np.abs(goal - self.q_ref) / v))
        self.auto = Auto(which, Quintic(self.q_ref.copy(), goal, duration), t)
        self._note(t, f"{which}: {duration:.1f} s")

    # -- the reference, and the servo -------------------------------------------------------------------

    def _advance_auto(self, t: float) -> None:
        auto = self.auto
        x, xd, _ = auto.trajectory.sample(np.array([t - auto.t0]))
        self.q_ref, self.qd_ref = x[0], xd[0]
        if t - auto.t0 >= auto.trajectory.duration:
            self.patches.replayed(t, auto)
            self.auto = None
            self.qd_ref = np.zeros_like(self.qd_ref)

    def compute(self, t, q, qd, q_ref, qd_ref, qdd_ref):
        dt, queue = self.ctx.control_dt, self.patches.replay_queue
        if self.q_ref is None:
            self.q_ref = q.copy()
        while self.keys and self.keys[0].at <= t + 1e-9:
            k = self.keys.pop(0)
            self._press(t, k.key, k.hold_s, q, qd)
        while queue and queue[0][0] <= t + 1e-9:
            _, key, hold = queue.pop(0)
            self.jog = self.jogger.start(key, t + hold, self.q_ref)
        if self.auto is not None:
            self._advance_auto(t)
        elif self.jog is not None:
            new = self.jogger.advance(self.jog, t, dt, self.q_ref)
            if new is self.q_ref:
                self._note(t, f"'{self.jog.key}': the arm can go no further (reach, joint limit or singularity)")
            if new is None or new is self.q_ref:
                self.jog, self.qd_ref = None, np.zeros_like(self.qd_ref)
            else:
                self.qd_ref, self.q_ref = (new - self.q_ref) / dt, new
        self.patches.due(t, q, self.selected)
        self.joint_reference = self.q_ref
        return self.kp * (self.q_ref - q) + self.kd * (self.qd_ref - qd) + self.robot.gravity_torque(q)

    def run_metrics(self, trace) -> dict[str, float]:
        return self.patches.stats.metrics()


@hookimpl
def rehabkit_register_controllers(registry) -> None:
    registry.add("arm-keypad", config=ArmKeypadConfig, factory=ArmKeypad)
