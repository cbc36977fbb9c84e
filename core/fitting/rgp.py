# SPDX-License-Identifier: LGPL-2.1-or-later
"""Relaxed Gradient Projection on base-mesh vertices (paper Sect. 2.5, Eqs. 6, 10, 11).

:class:`FitProblem` evaluates the paper's problem for base positions ``V0``:
fine vertices ``X = M V0`` (Eq. 10; ``M`` is ``S_i`` or a limit mask times ``S_i``),
objective ``-f_volume + p f_packaging`` and the thickness constraint, with every
fine-mesh gradient mapped back by ``M^T`` (Eq. 11).

Normalisation: the objective is evaluated as

    J = -f_volume / A_0 + (p / p_ref) * f_packaging / n_fine,

with ``A_0`` the initial fine-mesh area and ``n_fine`` the number of fine vertices, so
both terms are lengths (volume per area, mean penetration) and their gradients per
fine vertex are comparable: about ``a_j / A_0 ~ 1 / n_fine`` for the volume and
``(p / p_ref) / n_fine`` for a vertex outside the target. The paper's ``p = 1e5``
multiplies a length against a volume in its model units, so it has no unit-free
meaning; with ``p_ref = 1e3`` (:class:`RGPSettings`) it becomes a pull-back 100 times the
volume push, well above the exact-penalty threshold (about 1) of this L1 penalty. Much larger ratios
make the far, small entries of ``S_i^T`` carry the penalty of a few outside vertices
to the whole base mesh, and every vertex then oscillates (measured on a 3x3x3 grid
sphere: ratio 1e1 or 1e2 reaches 0.06 % of the bbox diagonal mean distance within
40 iterations, 1e3 or 1e4 stalls at 1.5 %).

Step rule: the search direction is divided by the largest base-vertex length of the
volume term's gradient and every vertex's row is clipped to length 1, then scaled
by ``step`` (model units) and a per-vertex damping factor that shrinks (``shrink``) when
the vertex's move reverses (zig-zag) and grows (``grow``, up to 1) otherwise.

:func:`run_rgp` is the optimiser of Antonau, Hojjat and Bletzinger (2021) as we read
it: per constraint a buffer zone around a moving centre; a constraint inside or above
its zone is active with buffer value ``w`` in [0, 2]; the search direction is the
objective gradient with the active constraint gradients' components removed by the
relaxation coefficients ``min(w, 1)``, plus a correction along the constraint
gradients with coefficients ``2 (w - 1)`` for ``w > 1``; an inner loop raises the
relaxation (then the correction) while the linearised step would still violate a
constraint; zone sizes follow the largest observed constraint change and grow when
the constraint zig-zags. """
import copy
from dataclasses import dataclass, field

import numpy as np

from core.fitting.responses import (InsideBounds, packaging, thickness_constraint,
                                    volume)
from core.progress import NO_PROGRESS
from core.tolerances import CONTACT


@dataclass(frozen=True)
class RGPSettings:
    """Tuned constants of the relaxed gradient projection (:func:`run_rgp`)."""

    p_ref: float = 1e3
    """Penalty ``p`` at which the packaging pull-back equals the volume push per fine vertex
    (the objective's normalisation, see the module docstring)."""
    moving: float = 0.05
    """Length of a search-direction row (at most 1) above which a vertex counts as moving,
    for the zig-zag test of its damping."""
    reversal: float = 1e-6
    """A moving vertex's move reverses (zig-zag) when the cosine between it and its previous
    move is below ``-reversal``. Moves at right angles (common on a symmetric part, where a
    vertex slides along one axis and then along another) have a cosine of rounding size,
    whose sign would otherwise decide the damping."""
    shrink: float = 0.7
    """Factor on a vertex's damping when its move reverses (zig-zag)."""
    grow: float = 1.5
    """Factor on a vertex's damping when its move does not reverse (up to 1)."""
    min_damping: float = 1e-3
    """Smallest damping factor of a vertex."""


RGP = RGPSettings()
"""The settings this module runs with."""


class FitProblem:
    """The fit problem of Eq. 6 on base positions.

    Parameters
    ----------
    mapping : (n_fine, n_base) scipy sparse matrix ``M``, ``X = M @ V0``.
    triangles : (t, 3) int64 triangles of the fine mesh (outward orientation).
    target : core.target_surface.TargetSurface
    penalty : float > 0, ``p`` of Eq. 6.
    mode : ``'inside'`` or ``'nearest'`` (see :func:`core.fitting.responses.packaging`).
    t_min : float >= 0, minimal wall thickness in model units; 0 disables it.
    area : float > 0, ``A_0`` of the normalisation (model units squared).
    """

    def __init__(self, mapping, triangles, target, penalty, mode, t_min, area):
        self.mapping = mapping.tocsr()
        self.mapping_t = self.mapping.T.tocsr()
        self.triangles = triangles
        self.target = target
        self.weight = float(penalty) / RGP.p_ref
        self.mode = mode
        self.t_min = float(t_min)
        self.area = float(area)
        # queries of the points proven still inside are skipped (exact, see InsideBounds)
        self.known = InsideBounds(CONTACT * target.diagonal) if mode == "inside" else None

    def with_t_min(self, t_min):
        """The same problem with the minimal wall thickness ``t_min`` (model units; 0: no
        constraint), sharing this one's matrices and its cache of points known inside."""
        other = copy.copy(self)
        other.t_min = float(t_min)
        return other

    def fine(self, V0):
        """(n_fine, 3) float64 fine positions ``M V0`` (Eq. 10)."""
        return self.mapping @ V0

    def evaluate(self, V0):
        """Objective, constraints and their base-mesh gradients.

        Returns
        -------
        Evaluation
        """
        X = self.fine(V0)
        n_fine = len(X)
        vol, d_vol = volume(X, self.triangles)
        pack, d_pack, signed = packaging(X, self.target, self.mode, self.known)
        objective = -vol / self.area + self.weight * pack / n_fine
        grad_volume = self.mapping_t @ (-d_vol / self.area)
        grad = grad_volume + self.mapping_t @ (self.weight * d_pack / n_fine)
        constraints = []
        figures = {"volume": vol, "packaging": pack,
                   "max_outside": float(max(signed.max(), 0.0))}
        if self.t_min > 0:
            g, d_g, t_found = thickness_constraint(X, self.triangles, self.t_min)
            constraints.append(Constraint("thickness", g, self.mapping_t @ d_g))
            figures["min_thickness"] = t_found
        scale = float(np.linalg.norm(grad_volume, axis=1).max())
        return Evaluation(objective, grad, constraints, figures, scale)


@dataclass
class Constraint:
    """One inequality constraint ``value <= 0`` with its base-mesh gradient (n, 3)."""

    name: str
    value: float
    gradient: np.ndarray


@dataclass
class Evaluation:
    """Objective value, (n, 3) base gradient, constraints, figures, gradient scale.

    ``scale`` is the gradient length at which a vertex takes a full step (for the
    fit: the largest base-vertex length of the volume term's gradient).
    """

    objective: float
    gradient: np.ndarray
    constraints: list
    figures: dict
    scale: float


@dataclass
class BufferZone:
    """Buffer-zone state of one constraint (RGP).

    The zone is ``[centre - size, centre + size]``; ``size`` is ``factor`` times the
    largest constraint change seen so far (at least ``min_size``).
    """

    size: float
    min_size: float = 1e-6
    centre: float = 0.0
    factor: float = 2.0
    max_change: float = 0.0
    values: list = field(default_factory=list)
    buffer_values: list = field(default_factory=list)

    def assess(self, value):
        """Record ``value``; return the buffer value ``w`` (0 = inactive, up to 2)."""
        if self.values:
            self.max_change = max(self.max_change, abs(value - self.values[-1]))
            self.size = max(self.factor * self.max_change, self.min_size)
        self.values.append(value)
        lower = self.centre - self.size
        w = 0.0 if value < lower else min((value - lower) / self.size, 2.0)
        self.buffer_values.append(w)
        return w

    def adapt(self):
        """After a step: widen on zig-zag, move the centre after violations."""
        g = self.values
        if len(g) >= 4:
            d1, d2, d3 = g[-1] - g[-2], g[-2] - g[-3], g[-3] - g[-4]
            if d1 * d2 < 0 and d2 * d3 < 0:
                self.factor += abs(self.buffer_values[-1] - self.buffer_values[-2])
        if len(g) >= 2:
            if g[-1] > 0 and g[-1] >= g[-2]:
                self.centre -= g[-1]
            elif g[-1] < 0 and g[-1] <= g[-2]:
                self.centre = 0.0


@dataclass
class RGPResult:
    """Outcome of :func:`run_rgp`.

    vertices : (n, 3) float64 best design found (lowest objective among iterates that
        satisfy the constraints, else the last).
    iterations : int, optimisation iterations run.
    history : dict of lists, one entry per iteration: ``objective``, ``step``,
        ``active`` (names of active constraints) and every figure of the evaluation.
    stopped : str, ``'iterations'`` or ``'stalled'``.
    best_iteration : int
    """

    vertices: np.ndarray
    iterations: int
    history: dict
    stopped: str
    best_iteration: int


def run_rgp(problem, V0, step, iterations=100, stall_tol=1e-4, patience=10,
            max_inner=10, initial_buffer=0.2, progress=NO_PROGRESS, fixed=None):
    """Minimise ``problem`` from base positions ``V0`` with relaxed gradient projection.

    Parameters
    ----------
    problem : object with ``evaluate(V) -> Evaluation``.
    V0 : (n, 3) float64 initial base positions.
    step : float > 0, largest vertex move per iteration (model units).
    iterations : int >= 0, maximum number of updates.
    stall_tol : float, stop when the best objective improved by less than
        ``stall_tol * max(|best|, step)`` over the last ``patience`` iterations.
    patience : int >= 1
    max_inner : int >= 1, inner iterations for relaxation / correction.
    initial_buffer : float > 0, buffer-zone half width before any change was seen
        (in the constraint's own, dimensionless units).
    progress : core.progress.Progress
    fixed : (n,) bool or None, base vertices that keep their position (their rows of the
        search direction are zero).

    Returns
    -------
    RGPResult
    """
    V = np.array(V0, dtype=np.float64)
    damping = np.ones(len(V))
    previous = np.zeros_like(V)
    zones = {}
    history = {"objective": [], "step": [], "active": []}
    best = (np.inf, None, -1)
    stopped = "iterations"
    done = 0
    for it in range(iterations + 1):
        progress.check_cancel()
        ev = problem.evaluate(V)
        _record(history, ev)
        feasible = all(c.value <= 0 for c in ev.constraints)
        if feasible and ev.objective < best[0]:
            best = (ev.objective, V.copy(), it)
        if it == iterations or _stalled(history["objective"], step, stall_tol, patience):
            stopped = "iterations" if it == iterations else "stalled"
            break
        weights = _buffer_weights(ev.constraints, zones, initial_buffer)
        active = [c for c in ev.constraints if c.name in weights]
        direction = _search_direction(ev, active, weights, damping, step, max_inner)
        if fixed is not None:
            direction[fixed] = 0.0
        damping = _damped(damping, direction, previous)
        update = direction * (step * damping)[:, None]
        V = V + update
        previous = direction
        for zone in zones.values():
            zone.adapt()
        history["step"].append(float(np.linalg.norm(update, axis=1).max()))
        history["active"].append([c.name for c in active])
        done = it + 1
        progress.report("fit", done / max(iterations, 1), f"iteration {done}")
    if best[1] is None:
        best = (history["objective"][-1], V, len(history["objective"]) - 1)
    return RGPResult(best[1], done, history, stopped, best[2])


def _buffer_weights(constraints, zones, initial_buffer):
    """Buffer value ``w`` in (0, 2] of each active constraint (name -> float): those inside
    or above their buffer zone (``zones``, created with ``initial_buffer``) with a nonzero
    gradient."""
    weights = {}
    for c in constraints:
        zone = zones.setdefault(c.name, BufferZone(size=initial_buffer))
        w = zone.assess(c.value)
        if w > 0 and np.abs(c.gradient).max() > 0:
            weights[c.name] = w
    return weights


def _damped(damping, direction, previous):
    """(n,) float64 damping factors after a move along ``direction`` ((n, 3)) that followed
    ``previous``: shrunk where a moving vertex reverses, grown (up to 1) elsewhere."""
    length, previous_length = (np.linalg.norm(direction, axis=1),
                               np.linalg.norm(previous, axis=1))
    moving = (length > RGP.moving) & (previous_length > RGP.moving)
    reversed_ = moving & (np.einsum("ij,ij->i", direction, previous)
                          < -RGP.reversal * length * previous_length)
    return np.where(reversed_, np.maximum(RGP.shrink * damping, RGP.min_damping),
                    np.minimum(RGP.grow * damping, 1.0))


def _record(history, ev):
    history["objective"].append(float(ev.objective))
    for key, value in ev.figures.items():
        history.setdefault(key, []).append(float(value))
    for c in ev.constraints:
        history.setdefault(c.name, []).append(float(c.value))


def _stalled(objective, step, tol, patience):
    if len(objective) <= patience:
        return False
    best_now = min(objective)
    best_before = min(objective[:-patience])
    return best_before - best_now < tol * max(abs(best_now), step)


def _search_direction(ev, active, weights, damping, step, max_inner):
    """(n, 3) float64 search direction of one RGP iteration, every row of length <= 1."""
    f = ev.gradient.reshape(-1) / ev.scale if ev.scale > 0 else _unit_max(ev.gradient.reshape(-1))
    if not active:
        return _clip_rows(-f.reshape(-1, 3))
    N = np.stack([_unit_max(c.gradient.reshape(-1)) for c in active])
    gram = N @ N.T
    gram += 1e-12 * np.trace(gram) * np.eye(len(active))
    lam = np.linalg.solve(gram, N @ f)
    correction_dir = -N.T @ np.linalg.solve(gram, np.ones(len(active)))
    w = np.array([weights[c.name] for c in active])
    relax = np.minimum(w, 1.0)
    correct = np.where(w > 1.0, 2.0 * (w - 1.0), 0.0)
    scale = np.repeat(step * damping, 3)
    for _ in range(max_inner):
        p = -(f - N.T @ (relax * lam))
        c = -N.T @ np.linalg.solve(gram, correct)
        c_len = np.linalg.norm(c.reshape(-1, 3), axis=1).max()
        if c_len > 0:
            c *= correct.max() / c_len
        s = p + c
        if not np.abs(s).max() > 0:
            s = _unit_max(correction_dir)
        s = _clip_rows(s.reshape(-1, 3)).reshape(-1)
        predicted = np.array([con.value + con.gradient.reshape(-1) @ (s * scale)
                              for con in active])
        if not (predicted > 0).any():
            break
        grow = predicted > 0
        bump = 2.0 / max_inner
        raise_relax = grow & (relax < 1.0)
        raise_corr = grow & ~raise_relax & (correct < 2.0)
        if not (raise_relax.any() or raise_corr.any()):
            break
        relax = np.where(raise_relax, np.minimum(relax + bump, 1.0), relax)
        correct = np.where(raise_corr, np.minimum(correct + bump, 2.0), correct)
    return s.reshape(-1, 3)


def _clip_rows(s):
    """Scale the rows of (n, 3) ``s`` that are longer than 1 down to length 1."""
    length = np.linalg.norm(s, axis=1, keepdims=True)
    return s / np.maximum(length, 1.0)


def _unit_max(x):
    norm = np.abs(x).max()
    return x / norm if norm > 0 else x
