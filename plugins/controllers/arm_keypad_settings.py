"""The ARM keypad's settings: the key timeline a scenario lists (walked through the menus when it is validated, each
wrong press located at its line), the patch store, jog speeds, preprogrammed postures and servo gains."""

from __future__ import annotations

from pydantic import Field, ValidationError, model_validator
from pydantic_core import InitErrorDetails, PydanticCustomError
from rehabkit_plugins.controllers.arm_keypad_menu import check_timeline

from rehabkit.plugin import StrictModel


class KeyPress(StrictModel):
    """One press of a keypad button."""

    at: float = Field(ge=0, description="[s] from the start")
    key: str
    hold_s: float = Field(0.2, gt=0, description="how long it is held [s] (jog keys move while held)")


class ArmKeypadConfig(StrictModel):
    """Key timeline, patch store, jog speeds, preprogrammed postures and servo gains."""

    keys: list[KeyPress] = Field(description="the user's key presses, in time order")
    store: str = Field("user", description="'user' (the user's data directory), 'run' (a fresh store in the "
                                           "run's output folder; in memory for a run that writes none) or a path to "
                                           "a patch store file")
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
