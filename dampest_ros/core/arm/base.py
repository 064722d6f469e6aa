"""Base parameters: the combinations of the full parameters that joint torques determine.

A serial arm's regressor has dependent columns whatever the motion (a link's inertia about
an axis that never turns, parameters that only ever act together with the next link's).
QR with column pivoting of the regressor stacked over random states, W P = Q R, splits the
columns into r independent and p − r dependent ones; with R = [[R11, R12], [0, ~0]],

    Y_dep = Y_ind β,  β = R11⁻¹ R12,   so   Y π = Y_ind (π_ind + β π_dep) = Y_b π_b

(Gautier 1991). The base regressor is Y_b = Y[:, ind]; π_b = π_ind + β π_dep.

Rounding. Both decisions are relative, with one tolerance ``tol``: a column whose norm is
below tol × the largest column norm is structurally zero (a URDF joint frame turned by
rpy = π/2 leaves cos(π/2) = 6e-17 where the algebra has 0: norms of 1e-32 or 1e-14 against
O(10)) and is set to zero *before* the columns are scaled to unit norm, which would otherwise
make rounding a direction as large as any other and count it as a base parameter; the rank
is the number of pivots |R_kk| above tol × |R_00|.

What float64 resolves sets tol = 1e-5, not rounding alone. A URDF that writes π/2 to five
digits (rpy = 1.5708, the xArm7's) turns its axes 3.7e-6 rad off square: a combination that
the algebra folds becomes independent with a pivot of 5e-6, a direction no measured torque
resolves. The fits solve normal equations, which square the regressor's condition, and a
measured trajectory adds its own 10²–10³: (1/5e-6 × 10³)² ≈ 1e16 is float64's end, and the
information matrix was singular. Such a direction is folded like an exact dependency; the
model error of the fold is its pivot's relative size (5e-6 of a torque). Every kept pivot of
the arms tried (UR3, UR5, UR10, Z1, Kinova Jaco, Panda, xArm7) is above 0.4 × |R_00|.

The pivot test alone does not catch every such frame. The SO-101 (example-robot-data) writes
π as 3.14159 and π/2 as 1.5708 in joints whose links are light: a link's mass column, which
the algebra zeroes, is left at 1e-4 of the largest column, above the column test, and scaled
to unit norm it took a pivot, leaving two genuine combinations at pivots of 5e-4 and 4e-4
(49 base parameters where there are 47), and the information matrix of a 60 s trajectory was
singular. So the split is also made for the arm with its joint frames turned exactly square
wherever a rotation entry is within ``tol`` of 0 (:func:`square_frames`); when that has fewer
independent columns, the others were rounding and its split is taken, β coming from the arm
as it is (least squares). Every arm above has as many either way and keeps its split and β.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from dampest_ros.core.arm.model import ArmModel
from dampest_ros.core.arm.regressor import parameter_names, regressor

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class BaseParameters:
    """The split of the full parameters into base combinations.

    Attributes
    ----------
    names : list of str, length p
        Full parameter names.
    independent : ndarray of int, shape (b,)
        Columns kept (ascending).
    dependent : ndarray of int, shape (p − b,)
        Columns folded into the kept ones.
    beta : ndarray, shape (b, p − b)
        π_b = π[independent] + beta @ π[dependent].
    """

    names: list[str]
    independent: NDArray[np.int64]
    dependent: NDArray[np.int64]
    beta: FloatArray

    @property
    def size(self) -> int:
        """b, the number of base parameters."""
        return len(self.independent)

    def of(self, full: FloatArray) -> FloatArray:
        """Base parameters of a full parameter vector, shape (p,) → (b,)."""
        full = np.asarray(full, dtype=float)
        return full[self.independent] + self.beta @ full[self.dependent]

    def columns(self, Y: FloatArray) -> FloatArray:
        """The base regressor: the independent columns of Y, shape (..., p) → (..., b)."""
        return Y[..., self.independent]

    def mapping(self, tol: float = 1e-10) -> list[str]:
        """One line per base parameter: its name and the full parameters it combines,
        e.g. ``b3 = elbow_joint.Izz + 0.425 wrist_1_joint.my + 0.18 wrist_1_joint.m``."""
        lines = []
        for k, i in enumerate(self.independent):
            terms = [self.names[i]]
            for c, d in zip(self.beta[k], self.dependent, strict=True):
                if abs(c) > tol:
                    terms.append(f"{'+' if c > 0 else '-'} {abs(c):.6g} {self.names[d]}")
            lines.append(f"b{k + 1} = " + " ".join(terms))
        return lines

    def unidentifiable(self, tol: float = 1e-10) -> list[str]:
        """Full parameters that no base parameter contains (no motion excites them)."""
        used = np.abs(self.beta).max(axis=0) > tol if self.beta.size else np.zeros(0, bool)
        return [self.names[d] for d, u in zip(self.dependent, used, strict=True) if not u]


def random_states(n: int, samples: int, seed: int
                  ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Random joint states of no particular trajectory: positions uniform within ±π,
    velocities and accelerations standard normal.

    Parameters
    ----------
    n : int
        Joints.
    samples : int
    seed : int

    Returns
    -------
    q, qd, qdd : ndarray, shape (samples, n)
        rad, rad/s, rad/s².
    """
    rng = np.random.default_rng(seed)
    q = rng.uniform(-np.pi, np.pi, (samples, n))
    qd = rng.normal(size=(samples, n))
    qdd = rng.normal(size=(samples, n))
    return q, qd, qdd


def square_frames(arm: ArmModel, tol: float = 1e-5) -> ArmModel:
    """The arm with the rotation entries of its joint frames within ``tol`` of 0 set to 0
    and each frame made orthonormal again (the nearest rotation): a URDF's rounded π/2 or π
    (1.5708, 3.14159) turned exactly square, real angles kept. The arm itself when no entry
    is that close to 0 without being 0.

    Parameters
    ----------
    arm : ArmModel
    tol : float
        Largest |entry| taken as 0.

    Returns
    -------
    ArmModel
    """
    r = arm.rotation
    off = (np.abs(r) <= tol) & (r != 0.0)
    if not off.any():
        return arm
    u, _, vt = np.linalg.svd(np.where(off, 0.0, r))
    return replace(arm, rotation=u @ vt)


def _split(W: FloatArray, tol: float) -> tuple[NDArray[np.int64], NDArray[np.int64],
                                               FloatArray]:
    """Independent and dependent columns of a stacked regressor W (R, p) by QR with column
    pivoting, and β (r, p − r) with W_dep = W_ind β (module docstring)."""
    # columns of rounding only are zero; the others scaled to unit norm so the pivoting
    # ranks directions, not units
    norm = np.linalg.norm(W, axis=0)
    live = norm > tol * norm.max()
    norm[~live] = 1.0
    _, R, perm = scipy.linalg.qr(np.where(live, W / norm, 0.0), mode="economic",
                                 pivoting=True)
    diag = np.abs(np.diag(R))
    r = int(np.sum(diag > tol * diag[0]))
    ind, dep = perm[:r], perm[r:]
    # β in the scaled columns, then back: Y_dep = Y_ind β  (β = R11⁻¹ R12, unscaled)
    beta_s = scipy.linalg.solve_triangular(R[:r, :r], R[:r, r:])
    return ind, dep, beta_s * norm[dep][None, :] / norm[ind][:, None]


def base_parameters(arm: ArmModel, samples: int = 400, seed: int = 0,
                    tol: float = 1e-5) -> BaseParameters:
    """Base parameters of an arm's full regressor (rigid body and joint columns), from
    ``samples`` random states (positions within ±π, velocities and accelerations of unit
    scale: structural dependencies only, not those of one trajectory).

    Parameters
    ----------
    arm : ArmModel
    samples : int
        Random states stacked.
    seed : int
    tol : float
        Relative tolerance: a column whose norm is at most tol × the largest column norm is
        structurally zero; a pivot |R_kk| at most tol × |R_00| ends the independent set
        (see the module docstring for why 1e-5); a rotation entry of a joint frame within
        tol of 0 is 0 for the split (:func:`square_frames`).

    Returns
    -------
    BaseParameters
    """
    states = random_states(arm.n, samples, seed)
    W = regressor(arm, *states).reshape(samples * arm.n, -1)
    ind, dep, beta = _split(W, tol)
    square = square_frames(arm, tol)
    if square is not arm:
        ind_sq, dep_sq, _ = _split(regressor(square, *states).reshape(W.shape), tol)
        if len(ind_sq) < len(ind):  # the extra columns were rounding: fold them
            ind, dep = ind_sq, dep_sq
            norm = np.maximum(np.linalg.norm(W, axis=0), 1e-300)
            # Y_dep = Y_ind β in the least-squares sense, in scaled columns then back
            beta = np.linalg.lstsq(W[:, ind] / norm[ind], W[:, dep] / norm[dep],
                                   rcond=None)[0] * norm[dep][None, :] / norm[ind][:, None]
    order = np.argsort(ind)
    return BaseParameters(parameter_names(arm), ind[order].astype(np.int64),
                          dep.astype(np.int64), beta[order])
