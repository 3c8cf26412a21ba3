"""Test-rig loads (``world.loads``) applied to a compiled MuJoCo scene: the MuJoCo backend's and the MuJoCo plant's
behind a bridge, so that a push is the same push in simulation and over the link."""

from __future__ import annotations

import mujoco
import numpy as np

from rehabkit.core.plugins.names import suggest


class LoadApplier:
    """Sets each load's force (world frame, at its body's centre of mass) for the time given."""

    def __init__(self, model: mujoco.MjModel, loads):
        self.loads = list(loads)
        bodies = [model.body(i).name for i in range(model.nbody)]
        for load in self.loads:
            if load.body not in bodies:
                raise ValueError(f"world.loads '{load.name}': no body '{load.body}' in the scene"
                                 f"{suggest(load.body, bodies)}")
        self.ids = np.array([model.body(x.body).id for x in self.loads], int)
        self.forces = np.array([x.force_n for x in self.loads], float).reshape(-1, 3)

    def __bool__(self) -> bool:
        return bool(self.loads)

    def apply(self, data: mujoco.MjData, t: float) -> None:
        frc = data.xfrc_applied
        frc[self.ids, :3] = 0.0
        for i, load in enumerate(self.loads):
            frc[self.ids[i], :3] += load.at(t) * self.forces[i]
