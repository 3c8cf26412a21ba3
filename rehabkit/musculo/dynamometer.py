"""A dynamometer in simulation: a person with a musculoskeletal model strapped to a one-joint robot, stepped as a
clinical test bench is — the lever held (isometric), driven at a set speed (isokinetic: a Tardieu test), or left
free with its own weight compensated (transparent). The person's torque is what the straps put on the lever.

``examples/robots/elbow_dynamometer.yaml`` is such a scenario (MyoElbow on an elbow lever); the tests of the
musculoskeletal patient and its benchmark run their protocols here.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from rehabkit.core.run.runner import Runner
from rehabkit.core.scenario.loader import load_scenario

MVC = np.array([300.0])  # an elbow-flexion torque far beyond anyone's: the muscles give all they have [N·m]
RIGID = {"patient.model.straps.stiffness_n_m": 50000.0, "patient.model.straps.damping_ns_m": 500.0}
Lever = Callable[[float], tuple[float, float]]


class Dynamometer:
    """The scenario's one-joint robot with the person strapped in, stepped one control period at a time.

    ``driven``: a motor-driven lever the person cannot move (its angle is imposed by :meth:`run`'s ``lever``).
    """

    def __init__(self, scenario: str | Path, overrides: dict | None = None, driven: bool = False, q0: float = 0.0):
        self.a = Runner(load_scenario(scenario, overrides or {})).build()
        self.backend, self.person, self.robot = self.a.backend, self.a.patient, self.a.robot
        self.m, self.d = self.backend.model, self.backend.data
        joint = self.m.joint(self.robot.model.joint_names[0]).id
        self.dof, self.qadr = int(self.m.jnt_dofadr[joint]), int(self.m.jnt_qposadr[joint])
        if driven:
            self.m.dof_armature[self.dof] += 1000.0  # before the reset: the straps' stiffness is set from it
        self.backend.reset(np.array([q0]))
        self.dt = self.a.context.control_dt
        self.sub = round(self.dt / self.backend.timestep)

    def run(self, seconds: float, request: Callable[[float], np.ndarray] | None = None, lever: Lever | None = None,
            goal: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Step for ``seconds``. ``request(t)``: the torque the person wants at their driven joints (default: their
        own drive toward ``goal``); ``lever(t)``: the lever's (angle, speed) imposed (default: free, its weight
        compensated). Returns per step: t, the straps' torque on the lever (tau), the lever's q and qd, the
        largest strap force, the elbow flexors' largest excitation."""
        out: dict[str, list] = {"t": [], "tau": [], "q": [], "qd": [], "force": [], "flexors": []}
        t0, d = self.d.time, self.d
        flexors = self.person.arm.groups["elbow_flexors"]
        for _ in range(round(seconds / self.dt)):
            t = d.time - t0
            if lever is not None:
                d.qpos[self.qadr], d.qvel[self.dof] = lever(t)
            q = d.qpos[self.qadr : self.qadr + 1].copy()
            tau = request(t) if request is not None else self.person.intent(goal)
            excitation = self.person.excite(np.atleast_1d(tau))
            self.backend.command(self.robot.gravity_torque(q))
            self.backend.step(self.sub)
            out["t"].append(t)
            out["tau"].append(self.person.strap_torque()[0])
            out["q"].append(d.qpos[self.qadr])
            out["qd"].append(d.qvel[self.dof])
            out["force"].append(max(np.linalg.norm(f) for f in self.person.strap_forces()))
            out["flexors"].append(float(np.max(excitation[flexors])))
        return {k: np.asarray(v) for k, v in out.items()}


def isometric(scenario: str | Path, overrides: dict | None = None) -> tuple[float, float]:
    """The lever held at its zero: (the person's maximal flexion torque, their relaxed torque) on it [N·m]."""
    bench = Dynamometer(scenario, {**RIGID, **(overrides or {})}, driven=True)
    hold: Lever = lambda t: (0.0, 0.0)  # noqa: E731
    relaxed = bench.run(0.8, request=lambda t: np.zeros(1), lever=hold)["tau"][-25:].mean()
    mvc = bench.run(0.4, request=lambda t: MVC, lever=hold)["tau"][-25:].mean()
    return float(mvc), float(relaxed)


def tardieu(scenario: str | Path, speed_deg_s: float, overrides: dict | None = None,
            start_deg: float = -10.0, span_deg: float = 80.0) -> tuple[float, float]:
    """A relaxed elbow stretched by the lever at a constant speed over ``span_deg`` from ``start_deg``: the largest
    resistance [N·m] over the stretch's last two thirds (past the jolt of starting at full speed) and the elbow
    flexors' largest excitation."""
    start, span, w = np.radians(start_deg), np.radians(span_deg), np.radians(speed_deg_s)
    bench = Dynamometer(scenario, {**RIGID, **(overrides or {}), "patient.model.drive.own_weight": 0.0},
                        driven=True, q0=start)
    bench.run(0.2, request=lambda t: np.zeros(1), lever=lambda t: (start, 0.0))
    move = bench.run(span / w, request=lambda t: np.zeros(1), lever=lambda t: (start + w * t, w))
    late = slice(len(move["t"]) // 3, None)
    return float(-move["tau"][late].min()), float(move["flexors"].max())  # resisting: pushing the lever back
