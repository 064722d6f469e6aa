"""How far the believed model is trusted where an effect moves the data: a DOF whose held-out
residual grows only where an effect (a current) moves the relative velocity ν_r outside the
velocities the believed model was fitted on is extrapolation of that model, not evidence
against the effect (:func:`degradations`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.gap.data import FORCE_UNITS, GapData
from dampest_ros.core.gap.effects import Effect
from dampest_ros.core.physics.rigid_body import DOF_NAMES, FORCE_NAMES

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: share of the flown range per DOF by which ν_r may leave it and still count as inside
MARGIN = 0.05
#: fewer held-out rows inside the envelope than this share: the DOF cannot be judged there
MIN_INSIDE = 0.1
VELOCITY_UNITS = ("m/s", "m/s", "m/s", "rad/s", "rad/s", "rad/s")


@dataclass(frozen=True)
class Degradation:
    """A DOF whose held-out residual grows after a step.

    Attributes
    ----------
    dof : int
    before, after : float
        Held-out residual RMS (N, N·m).
    extrapolation : bool
        True when it grows only where the effects move ν_r outside the believed model's
        flown envelope, or inside it by less than the model's own error there (not evidence
        against the effect).
    why : str
        The reason in words.
    """

    dof: int
    before: float
    after: float
    extrapolation: bool
    why: str

    @property
    def text(self) -> str:
        """E.g. ``Z held-out RMS 1.89 → 2.62 N: relative velocity v reaches …``."""
        return (f"{FORCE_NAMES[self.dof]} held-out RMS {self.before:.3g} → {self.after:.3g} "
                f"{FORCE_UNITS[self.dof]}: {self.why}")


def relative_velocity(data: GapData, effects: Sequence[tuple[Effect, FloatArray]]
                      ) -> FloatArray | None:
    """The velocity the damping sees with ``effects`` on every row, shape (N, 6), or None
    when no effect moves it (:meth:`Effect.relative_velocity`)."""
    ch = data.chunk_at(slice(0, len(data.samples)))
    out = None
    for e, p in effects:
        nu = e.relative_velocity(data, ch, p)
        if nu is not None:
            out = nu if out is None else out + nu - ch.nu
    return out


def outside(data: GapData, nu_r: FloatArray) -> BoolArray:
    """Rows where ν_r leaves the believed model's flown envelope (:attr:`GapData.flown`,
    widened by :data:`MARGIN` of its range) in any component, shape (N,)."""
    lo, hi = data.flown
    m = MARGIN * (hi - lo)
    return np.asarray(np.any((nu_r < lo - m) | (nu_r > hi + m), axis=1))


def _grows(ms0: FloatArray, ms1: FloatArray, scale: FloatArray, data: GapData, k: int,
           min_change: float) -> BoolArray:
    """Per DOF: the mean square rises from ``ms0`` to ``ms1`` by more than the
    4 k / n_eff,train an effect with k unknowns fitted to noise adds, and the RMS by more
    than ``min_change`` × the force ``scale`` (N, N·m), shape like ``ms0``."""
    return np.asarray((ms1 > ms0 * (1.0 + 4.0 * k / max(data.n_eff_train, 1.0)))
                      & (np.sqrt(ms1) - np.sqrt(ms0) > min_change * scale))


def _envelope_words(data: GapData, nu_r: FloatArray, rows: BoolArray) -> str:
    """The component of ν_r that leaves the flown envelope furthest on ``rows``, in words."""
    lo, hi = data.flown
    span = np.maximum(hi - lo, 1e-9)
    v = nu_r[rows]
    excess = np.maximum(v - hi, lo - v) / span
    j = int(np.argmax(excess.max(axis=0)))
    reach = v[int(np.argmax(excess[:, j])), j]
    u = VELOCITY_UNITS[j]
    return (f"relative velocity {DOF_NAMES[j]} reaches {reach:+.2f} {u}, the believed model "
            f"was fitted on {DOF_NAMES[j]} in [{lo[j]:+.2f}, {hi[j]:+.2f}] {u}")


def degradations(data: GapData, effects: Sequence[tuple[Effect, FloatArray]],
                 r_before: FloatArray, r_after: FloatArray, k: int,
                 min_change: float) -> list[Degradation]:
    """The DOFs whose held-out residual grows from ``r_before`` to ``r_after``, each judged
    extrapolation or not.

    A DOF grows when its held-out mean square rises by more than an effect with k unknowns
    fitted to noise adds (4 k / n_eff,train) and its RMS by more than ``min_change`` of its
    force scale. Its rise is extrapolation when the new effect (the last of ``effects``)
    moves ν_r outside the believed model's flown envelope (:func:`outside`) and, on the
    held-out rows that stay inside, the DOF does not grow (or fewer than :data:`MIN_INSIDE`
    of them stay inside), or grows by less than the model's own error: its mean square by at
    most the square of its residual RMS on its own fit data (:attr:`GapData.model_rmse`; the
    effect moves the points where the model is evaluated, and away from its fit samples it
    is not more accurate than that).

    Parameters
    ----------
    data : GapData
    effects : sequence of (Effect, ndarray)
        All effects of the model after the step.
    r_before, r_after : ndarray, shape (N, 6)
        Residual before and after the step (N, N·m).
    k : int
        Unknowns of the new effect.
    min_change : float
        Smallest rise of a DOF's held-out RMS that counts, as a share of its force scale.

    Returns
    -------
    list of Degradation
    """
    te = data.test
    ms0 = np.mean(r_before[te] ** 2, axis=0)
    ms1 = np.mean(r_after[te] ** 2, axis=0)
    grows = _grows(ms0, ms1, data.force_scale, data, k, min_change)
    if not grows.any():
        return []
    # only the new effect's own move of ν_r excuses a rise (not a current named before it)
    nu_r = relative_velocity(data, effects[-1:])
    out_rows = outside(data, nu_r) & te if nu_r is not None else np.zeros_like(te)
    inside = te & ~out_rows
    share_out = float(out_rows.sum()) / max(float(te.sum()), 1.0)
    found = []
    for i in np.flatnonzero(grows):
        before, after = float(np.sqrt(ms0[i])), float(np.sqrt(ms1[i]))
        if nu_r is None or not out_rows.any():
            found.append(Degradation(int(i), before, after, False,
                                     "inside the believed model's flown envelope"))
            continue
        words = _envelope_words(data, nu_r, out_rows)
        if inside.sum() < MIN_INSIDE * te.sum():
            found.append(Degradation(int(i), before, after, True,
                                     f"{words} (ν_r outside it on {100 * share_out:.0f} % of "
                                     "the held-out rows: extrapolation)"))
            continue
        m0 = np.mean(r_before[inside, i] ** 2, keepdims=True)
        m1 = np.mean(r_after[inside, i] ** 2, keepdims=True)
        grown = bool(_grows(m0, m1, data.force_scale[i:i + 1], data, k, min_change)[0])
        own = float(data.model_rmse[i])
        within = float(m1[0] - m0[0]) <= own**2
        inner = (f"on the {100 * (1 - share_out):.0f} % of held-out rows inside it the RMS "
                 f"goes {float(np.sqrt(m0[0])):.3g} → {float(np.sqrt(m1[0])):.3g} "
                 f"{FORCE_UNITS[i]}")
        if grown and within:
            inner += (f", within the model's own error there (RMS {own:.3g} "
                      f"{FORCE_UNITS[i]} on its fit data)")
        ok = not grown or within
        found.append(Degradation(int(i), before, after, ok,
                                 f"{words}; {inner}"
                                 + (": extrapolation, not evidence against the effect" if ok
                                    else "")))
    return found
