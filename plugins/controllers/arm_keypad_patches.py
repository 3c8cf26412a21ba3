"""The ARM keypad's record and replay (after Stuyt et al.): targets and timed action sequences stored in the user's
patch store, replayed — a target through the scenario's planner, a sequence by re-issuing its key presses with their
timing — and how well each replay ended where its patch said (checked a settling time after it ends)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from rehabkit.control import Action, Patch
from rehabkit.plugin import PlanningError, Target

SETTLE_S = 1.0  # after a replay ends, the error to the stored target is measured this much later


@dataclass
class Auto:
    """An automatic motion under way: a replay's trajectory (``patch``: its slot, ``pose``: its target) or a
    preprogrammed posture's."""

    what: str
    trajectory: object
    t0: float
    patch: int | None = None
    pose: np.ndarray | None = None


@dataclass
class Stats:
    stored: int = 0
    sequences_stored: int = 0
    replays: int = 0
    sequences_replayed: int = 0
    replay_pos_err: list[float] = field(default_factory=list)
    replay_rot_err: list[float] = field(default_factory=list)
    sequence_err_deg: list[float] = field(default_factory=list)
    failures: int = 0

    def metrics(self) -> dict[str, float]:
        out = {"patches_stored": float(self.stored), "sequences_stored": float(self.sequences_stored),
               "replays": float(self.replays), "sequences_replayed": float(self.sequences_replayed),
               "replay_failures": float(self.failures)}
        if self.replay_pos_err:
            out["replay_position_error_m"] = max(self.replay_pos_err)
            out["replay_orientation_error_deg"] = max(self.replay_rot_err)
        if self.sequence_err_deg:
            out["sequence_replay_error_deg"] = max(self.sequence_err_deg)
        return out


class PatchBook:
    """The patches of one session: what is being recorded, what is being replayed, and the checks after."""

    RUN_STATE_NESTED = ("stats", "store")  # (changed in place as the run goes: a session snapshot takes them)

    def __init__(self, store, robot, arm, ramp_s: float, note: Callable[[float, str], None]):
        self.store, self.robot, self.arm, self.ramp_s, self.note = store, robot, arm, ramp_s, note
        self.model = robot.model
        self.stats = Stats()
        self.store_at: float | None = None
        self.recording: list[Action] | None = None
        self.record_start_q: np.ndarray | None = None
        self.last_action_end: float | None = None
        self.replay_queue: list[tuple[float, str, float]] = []  # (when, key, how long it is held)
        self.sequence_check: tuple[float, np.ndarray, np.ndarray] | None = None
        self.pending_check: tuple[float, np.ndarray] | None = None

    # -- recording ---------------------------------------------------------------------------------

    def start_recording(self, t: float, q: np.ndarray, slot: int | None) -> None:
        self.recording, self.record_start_q, self.last_action_end = [], q.copy(), None
        self.note(t, f"recording a sequence for patch {slot}")

    def record_jog(self, t: float, key: str, hold: float) -> None:
        """A jog pressed while recording: kept with the wait before it."""
        if self.recording is None:
            return
        if self.last_action_end is not None and t > self.last_action_end:
            self.recording.append(Action(command="wait", duration_s=round(t - self.last_action_end, 6)))
        self.recording.append(Action(command=key, duration_s=hold))
        self.last_action_end = t + hold

    def stop_recording(self, t: float, q: np.ndarray, slot: int | None) -> None:
        actions = [a for a in self.recording if a.command != "wait" or a.duration_s > 0]
        if not any(a.command != "wait" for a in actions):
            self.note(t, "nothing recorded: no action between 'circle' and 'square'")
        else:
            self.store.save(slot, Patch(kind="sequence", robot=self.model.name, actions=actions,
                                        net_motion_rad=(q - self.record_start_q).tolist()))
            self.stats.sequences_stored += 1
            self.note(t, f"patch {slot}: sequence of {sum(a.command != 'wait' for a in actions)} actions stored")
        self.recording = None

    def store_target(self, t: float, q: np.ndarray, slot: int | None) -> None:
        pose = self.robot.fk(q)
        self.store.save(slot, Patch(kind="target", robot=self.model.name, joints_rad=q.tolist(), pose=pose.tolist()))
        self.stats.stored += 1
        self.note(t, f"patch {slot}: target stored at {np.round(pose[:3, 3], 3).tolist()} m (base frame)")

    # -- replaying ---------------------------------------------------------------------------------

    def play(self, t: float, slot: int, q: np.ndarray, qd: np.ndarray, plan) -> Auto | None:
        """Replay patch ``slot``: a sequence is queued (``replay_queue``); a target is planned with ``plan`` and
        returned as the automatic motion to follow (None when there is none)."""
        patch = self.store.load(slot)
        if patch is None:
            self.note(t, f"patch {slot} is empty")
            return None
        if patch.robot != self.model.name:
            self.note(t, f"patch {slot} was recorded on robot '{patch.robot}', not '{self.model.name}'")
            return None
        if patch.kind == "sequence":
            at = t
            for a in patch.actions:
                if a.command != "wait":
                    self.replay_queue.append((at, a.command, a.duration_s))
                at += a.duration_s
            if patch.net_motion_rad is not None and len(patch.net_motion_rad) == self.model.dof:
                self.sequence_check = (at + self.ramp_s + SETTLE_S, q.copy(), np.asarray(patch.net_motion_rad))
            self.stats.sequences_replayed += 1
            self.note(t, f"play patch {slot}: sequence of {len(self.replay_queue)} actions")
            return None
        goal_q = np.asarray(patch.joints_rad)
        if len(goal_q) != self.model.dof:
            self.note(t, f"patch {slot} holds {len(goal_q)} joints; this arm has {self.model.dof}")
            return None
        target = Target(f"patch {slot}", q=goal_q, pose=np.asarray(patch.pose))
        try:
            made = plan(t, q, qd, [target])
        except PlanningError as exc:
            self.stats.failures += 1
            self.note(t, f"play patch {slot}: no path ({exc})")
            return None
        self.stats.replays += 1
        length = made.details.get("path_length_m")
        self.note(t, f"play patch {slot}: {made.trajectory.duration:.1f} s"
                     + (f", path {length:.3f} m" if length is not None else ""))
        return Auto(f"replay of patch {slot}", made.trajectory, t, slot, target.pose)

    def replayed(self, t: float, auto: Auto) -> None:
        """An automatic motion ended: a replayed target's pose is checked after it settles."""
        if auto.patch is not None:
            self.pending_check = (t + SETTLE_S, auto.pose)

    def due(self, t: float, q: np.ndarray, slot: int | None) -> None:
        """What is due at ``t``: the checks after replays, a target stored by a held 'store' key."""
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
            self.store_target(t, q, slot)
            self.store_at = None
