"""Genetic optimisation of joint paths through task points (after Carbone et al., eqs. 3-5).

An individual is a joint path made of legs, one per pair of consecutive task
points; each leg is a polyline of configurations. Fitness (lower is better):

    J = Λ + Σ d(Ξ_i, Ξ_i+1) + β · #{i : ρ_i < δ}

with Λ = ∞ if any configuration on the path collides (checked densely along
every segment on the joint matrix), d the joint-space distance, and the count
taken over the path resampled every ``ε`` so that it weighs time spent near
obstacles rather than the number of vertices. Operators: tournament selection,
leg-wise crossover (children keep every task point), mutation by moving,
deleting or inserting an intermediate configuration; elitism keeps the best.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rehabkit.cspace.joint_matrix import JointMatrix

Path = list[np.ndarray]  # one (k, n) array per leg, ends = task points


def resample(points: np.ndarray, step: float) -> np.ndarray:
    """A polyline (k, n) resampled every ``step`` of its length (ends kept)."""
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] < 1e-12:
        return points[:1]
    at = np.append(np.arange(0.0, s[-1], step), s[-1])
    return np.column_stack([np.interp(at, s, points[:, j]) for j in range(points.shape[1])])


@dataclass
class GAConfig:
    """GA settings (paper's fitness weights β, δ)."""

    population: int = 30
    generations: int = 60
    beta: float = 0.2  # added per configuration closer than delta [rad of path-length equivalent]
    delta: float = 0.15  # clearance below which a configuration is penalised [rad]
    mutation: float = 0.6  # probability an offspring is mutated
    sigma: float = 0.06  # size of a point move [rad]
    tournament: int = 3
    elite: int = 2


@dataclass
class GAResult:
    best: Path
    fitness: float
    history: list[float] = field(default_factory=list)  # best fitness per generation (index 0: initial)


class PathGA:
    """Optimises joint paths on a joint matrix."""

    def __init__(self, theta: JointMatrix, config: GAConfig, rng: np.random.Generator):
        self.theta, self.cfg, self.rng = theta, config, rng
        self.check_step = theta.step / 2
        self._legs: dict[int, tuple] = {}  # id(leg) -> (free, length, near); legs are never mutated

    def _leg(self, leg: np.ndarray) -> tuple[bool, float, int]:
        key = id(leg)
        hit = self._legs.get(key)
        if hit is not None and hit[3] is leg:
            return hit[:3]
        free = bool(self.theta.is_free(resample(leg, self.check_step)).all())
        length = float(np.linalg.norm(np.diff(leg, axis=0), axis=1).sum())
        near = int((self.theta.clearance(resample(leg, self.theta.step)) < self.cfg.delta).sum()) if free else 0
        self._legs[key] = (free, length, near, leg)  # holding the leg keeps its id unique
        return free, length, near

    def dense(self, path: Path) -> np.ndarray:
        return np.vstack([resample(leg, self.check_step) for leg in path])

    def length(self, path: Path) -> float:
        return float(sum(np.linalg.norm(np.diff(leg, axis=0), axis=1).sum() for leg in path))

    def fitness(self, path: Path) -> float:
        """J of eq. (3); legs shared between individuals are evaluated once."""
        legs = [self._leg(leg) for leg in path]
        if not all(free for free, _, _ in legs):
            return float("inf")  # Λ
        return sum(length for _, length, _ in legs) + self.cfg.beta * sum(near for _, _, near in legs)

    def min_clearance(self, path: Path) -> float:
        return float(self.theta.clearance(self.dense(path)).min())

    def _pick(self, pop: list[Path], fit: np.ndarray) -> Path:
        idx = self.rng.choice(len(pop), size=self.cfg.tournament, replace=False)
        return pop[idx[np.argmin(fit[idx])]]

    def _crossover(self, a: Path, b: Path) -> Path:
        return [(a if self.rng.random() < 0.5 else b)[k] for k in range(len(a))]  # legs are shared, never edited

    def _mutate(self, path: Path) -> Path:
        k = int(self.rng.integers(len(path)))
        leg = path[k]
        kind = self.rng.random()
        if len(leg) > 2 and kind < 0.4:  # move an intermediate configuration
            i = int(self.rng.integers(1, len(leg) - 1))
            leg = leg.copy()
            leg[i] = np.clip(leg[i] + self.rng.normal(0.0, self.cfg.sigma, leg.shape[1]), self.theta.lower,
                             self.theta.upper)
        elif len(leg) > 2 and kind < 0.7:  # shortcut: drop one
            i = int(self.rng.integers(1, len(leg) - 1))
            leg = np.delete(leg, i, axis=0)
        else:  # insert a displaced midpoint
            i = int(self.rng.integers(0, len(leg) - 1))
            mid = 0.5 * (leg[i] + leg[i + 1]) + self.rng.normal(0.0, self.cfg.sigma, leg.shape[1])
            leg = np.insert(leg, i + 1, np.clip(mid, self.theta.lower, self.theta.upper), axis=0)
        out = [x for x in path]
        out[k] = leg
        return out

    def run(self, population: list[Path]) -> GAResult:
        cfg = self.cfg
        pop = list(population)
        fit = np.array([self.fitness(p) for p in pop])
        history = [float(fit.min())]
        for _ in range(cfg.generations):
            order = np.argsort(fit)
            nxt = [pop[i] for i in order[: cfg.elite]]
            while len(nxt) < cfg.population:
                child = self._crossover(self._pick(pop, fit), self._pick(pop, fit))
                if self.rng.random() < cfg.mutation:
                    child = self._mutate(child)
                nxt.append(child)
            pop = nxt
            fit = np.array([self.fitness(p) for p in pop])
            history.append(float(fit.min()))
        best = int(np.argmin(fit))
        return GAResult(pop[best], float(fit[best]), history)
