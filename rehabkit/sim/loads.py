"""Test-rig loads (``world.loads``) applied to a compiled MuJoCo scene: the MuJoCo backend's and the MuJoCo plant's
behind a bridge, so that a push is the same push in simulation and over the link."""

from __future__ import annotations

import mujoco
import numpy as np

from rehabkit.core.kinds.names import suggest


class LoadApplier:
    """Sets each load's force (world frame, at its body's centre of mass) for the time given; a load through a
    spring (``stiffness_n_m``) measures how far its body has given way along it since the push began."""

    def __init__(self, model: mujoco.MjModel, loads):
        self.loads = list(loads)
        bodies = [model.body(i).name for i in range(model.nbody)]
        for load in self.loads:
            if load.body not in bodies:
                raise ValueError(f"world.loads '{load.name}': no body '{load.body}' in the scene"
                                 f"{suggest(load.body, bodies)}")
        self.ids = np.array([model.body(x.body).id for x in self.loads], int)
        self.forces = np.array([x.force_n for x in self.loads], float).reshape(-1, 3)
        self._contact: dict[int, np.ndarray] = {}  # a spring load's body position when its push began

    def __bool__(self) -> bool:
        return bool(self.loads)

    def reset(self) -> None:
        """A new episode: the spring loads' pushes begin again from where their bodies are then."""
        self._contact.clear()

    def apply(self, data: mujoco.MjData, t: float) -> None:
        frc = data.xfrc_applied
        frc[self.ids, :3] = 0.0
        for i, load in enumerate(self.loads):
            share = load.at(t)
            if load.stiffness_n_m is None or share == 0.0:
                frc[self.ids[i], :3] += share * self.forces[i]
                continue
            at = data.xipos[self.ids[i]]
            start = self._contact.setdefault(i, at.copy())
            full = float(np.linalg.norm(self.forces[i]))
            along = self.forces[i] / full
            # the spring's compression: the rig's advance less how far the body went along the push
            squeeze = share * full / load.stiffness_n_m - float((at - start) @ along)
            frc[self.ids[i], :3] += max(0.0, load.stiffness_n_m * squeeze) * along
