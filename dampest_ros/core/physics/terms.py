"""The damping terms by kind (linear, quadratic, cross, memory, added-mass, Coriolis,
residual) and the library of candidate terms that :mod:`dampest_ros.core.identification.selection`
searches.

Parameter names (SNAME style, ASCII; F is the force letter X..N, j, k velocity letters u..r).
A single-entry coefficient in row F acts on the column ν_j through α(ν); the names are

=========================  =====================  ==========  ============================
family (:data:`FAMILIES`)  regressor of F          name        α text (``Alpha.parse``)
=========================  =====================  ==========  ============================
linear                     ν_j                     ``F_j``     ``1``       (``Y_r``)
cross-flow (quadratic)     ν_j |ν_k|               ``F_jk``    ``|k|``     (``Y_vr``,
                                                                           ``X_uu``)
bilinear                   ν_j ν_k, j ≤ k          ``F_jxk``   ``k``       (``Z_uxw``: lift)
speed magnitude            ν_j ‖(u, v, w)‖         ``F_jU``    ``|U|``     (``X_uU``)
angular speed magnitude    ν_j ‖(p, q, r)‖         ``F_jW``    ``|W|``     (``K_pW``)
cross-flow speed           ν_j ‖(ν_k, ν_l)‖        ``F_jUkl``  ``|k,l|``   (``X_uUvw``,
                           (k, l both linear or                            ``K_pWqr``)
                           both angular; W then)
projected area (``area``)  ν_j ν_k² / ‖v‖ (k       ``F_jAk``   ``k^2/|U|`` (``X_uAv``,
                           linear), ν_j ν_k² / ‖ω‖             ``q^2/|W|``  ``K_pAq``)
                           (k angular)
cross-flow area            ν_j (ν_k² + ν_l²) / ‖v‖ ``F_jAkl``  ``|k,l|^2   (``X_uAvw``,
(``area``)                 (pairs as cross-flow                /|U|``      ``K_pAqr``)
                           speed; ‖ω‖ if angular)
=========================  =====================  ==========  ============================

The projected-area family is bluff-body drag with a direction-dependent area: the drag
ρ C A(v̂) ‖v‖ ν_j with the area interpolated by the squared direction cosines,
A(v̂) ≈ Σ_k A_k v_k² / ‖v‖², is Σ_k (ρ C A_k) ν_j v_k² / ‖v‖, linear in the A_k; the three
columns of one ν_j sum to ν_j ‖v‖ (MuJoCo's ellipsoid drag is of this kind). A body of
revolution about one axis (a torpedo about x) has one cross-flow area for every direction
across it, so its force depends on v² + w² together: the cross-flow area column
ν_j (v² + w²) / ‖v‖, the sum of two projected-area columns, is that force in one term (a
slender hull's lift-induced surge drag, u (v² + w²) / ‖v‖), which a search adding one column at
a time would not find from either half alone.

The bilinear name carries an ``x`` (times) so that it never equals the cross-flow name of the
same letters (Y_{v|r|} is ``Y_vr``, Y_{v r} is ``Y_vxr``); ν_j ν_k and ν_k ν_j are one column,
named with the letters in u..r order. A :class:`CrossSpec` without a name keeps the older
label (α letters without bars, e.g. ``Z_wu`` for Z ← w u); :func:`library` always names its
candidates as above, and a model file stores every name with its row, column and α text, so
both forms read back unchanged.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.alpha import Alpha, dof_index
from dampest_ros.core.physics.damping import Basis, DampingTerm, unit
from dampest_ros.core.physics.rigid_body import DOF_NAMES, FORCE_NAMES, ConfigError

FloatArray = NDArray[np.float64]


def linear_term(dofs: Iterable[str | int] = DOF_NAMES,
                off_diagonal: Iterable[tuple[str | int, str | int]] = ()) -> DampingTerm:
    """D_linear: diagonal X_u … N_r plus optional off-diagonal entries (e.g. ('Y', 'r'))."""
    bases = []
    for d in dofs:
        i = dof_index(d, "linear.dofs")
        bases.append(Basis(f"{FORCE_NAMES[i]}_{DOF_NAMES[i]}", unit(i, i)))
    for r, c in off_diagonal:
        i, j = dof_index(r, "linear.off_diagonal"), dof_index(c, "linear.off_diagonal")
        bases.append(Basis(f"{FORCE_NAMES[i]}_{DOF_NAMES[j]}", unit(i, j)))
    return DampingTerm("linear", "viscous skin friction and laminar drag, force ∝ ν", bases)


def quadratic_term(dofs: Iterable[str | int] = DOF_NAMES) -> DampingTerm:
    """D_quadratic: Σ_i |ν_i| Q_i with diagonal Q_i; parameters X_uu … N_rr (X_{u|u|}, …)."""
    bases = []
    for d in dofs:
        i = dof_index(d, "quadratic.dofs")
        n = DOF_NAMES[i]
        bases.append(Basis(f"{FORCE_NAMES[i]}_{n}{n}", unit(i, i), Alpha("abs", i)))
    return DampingTerm("quadratic", "form drag from flow separation, force ∝ ν|ν|", bases)


@dataclass(frozen=True)
class CrossSpec:
    """One cross-coupling coefficient: force row, velocity column and α, e.g. Y ← v·|r|."""

    row: int
    col: int
    alpha: Alpha
    name: str = ""

    @property
    def label(self) -> str:
        """The parameter name (given, or built from the force, column and α letters)."""
        if self.name:
            return self.name
        a = self.alpha.label().replace("|", "")
        return f"{FORCE_NAMES[self.row]}_{DOF_NAMES[self.col]}{'' if a == '1' else a}"

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> CrossSpec:
        """From ``{row: Y, col: v, alpha: '|r|', name: Y_vr}`` (name optional)."""
        try:
            return cls(dof_index(d["row"], "cross.row"), dof_index(d["col"], "cross.col"),
                       Alpha.parse(str(d.get("alpha", "1"))), str(d.get("name", "")))
        except KeyError as exc:
            raise ConfigError(f"cross.{exc.args[0]}", "missing") from None


def cross_term(specs: Sequence[CrossSpec]) -> DampingTerm:
    """D_cross: Σ_k α_k(ν) B_k with single off-diagonal (or diagonal) coupling bases."""
    bases = [Basis(s.label, unit(s.row, s.col), s.alpha) for s in specs]
    return DampingTerm("cross", "coupling between degrees of freedom from asymmetric flow, "
                       "e.g. sway–yaw", bases)


#: Named families of the term library (see the module docstring for their names).
FAMILIES = ("linear", "crossflow", "bilinear", "norm", "area")
#: The cross-flow planes of a body slender along u, v, w, p, q, r's axes in turn: the pairs
#: of the cross-flow speed ‖(ν_k, ν_l)‖ and cross-flow area (ν_k² + ν_l²) / ‖·‖ columns.
CROSS_PAIRS = ((1, 2), (0, 2), (0, 1), (4, 5), (3, 5), (3, 4))


def library_name(row: int, col: int, alpha: Alpha) -> str:
    """The library's name of a single-entry coefficient F ← ν_col α(ν) (module docstring).

    Parameters
    ----------
    row, col : int
        Force row 0..5 (X..N) and velocity column 0..5 (u..r).
    alpha : Alpha
        ``one``, ``abs``, ``lin``, ``norm``, ``anorm``, ``pnorm`` or ``area``; others fall
        back to
        :attr:`CrossSpec.label`.
    """
    f, n = FORCE_NAMES[row], DOF_NAMES
    k = alpha.kind
    if k == "one":
        return f"{f}_{n[col]}"
    if k == "abs":
        return f"{f}_{n[col]}{n[alpha.i]}"
    if k == "lin":
        a, b = sorted((col, alpha.i))
        return f"{f}_{n[a]}x{n[b]}"
    if k == "norm":
        return f"{f}_{n[col]}U"
    if k == "anorm":
        return f"{f}_{n[col]}W"
    if k == "pnorm":
        return f"{f}_{n[col]}{'U' if alpha.i < 3 else 'W'}{n[alpha.i]}{n[alpha.j]}"
    if k == "area":
        return f"{f}_{n[col]}A{n[alpha.i]}{n[alpha.j] if alpha.j >= 0 else ''}"
    return CrossSpec(row, col, alpha).label


def library(families: Sequence[str] = FAMILIES, rows: Iterable[str | int] = DOF_NAMES
            ) -> list[CrossSpec]:
    """Candidate coefficients of the named families, each a named :class:`CrossSpec`.

    Per force row: ``linear`` ν_j (6), ``crossflow`` ν_j|ν_k| (36, the quadratic X_uu among
    them), ``bilinear`` ν_j ν_k for j ≤ k (21, lift u·w, Magnus-like ω × v products),
    ``norm`` ν_j ‖v‖ and ν_j ‖ω‖ (12) and the cross-flow speeds ν_j ‖(v, w)‖, ν_j ‖(u, w)‖,
    ν_j ‖(u, v)‖, ν_j ‖(q, r)‖, ν_j ‖(p, r)‖, ν_j ‖(p, q)‖ (36), ``area`` ν_j ν_k² / ‖v‖
    and ν_j ν_k² / ‖ω‖ (36) and the cross-flow areas ν_j (v² + w²) / ‖v‖ … ν_j (p² + q²) / ‖ω‖
    over the same pairs (36). Every column appears once
    per row (ν_j ν_k and ν_k ν_j are one). Ordered simplest first, which decides which of two
    numerically equal columns a selection keeps.

    Parameters
    ----------
    families : sequence of str
        A subset of :data:`FAMILIES`.
    rows : iterable of str or int
        Force rows (X..N or 0..5).

    Returns
    -------
    list of CrossSpec
    """
    unknown = set(families) - set(FAMILIES)
    if unknown:
        raise ConfigError("families", f"unknown {sorted(unknown)}; use some of {FAMILIES}")
    alphas: list[tuple[int, Alpha]] = []
    if "linear" in families:
        alphas += [(j, Alpha("one")) for j in range(6)]
    if "crossflow" in families:
        alphas += [(j, Alpha("abs", k)) for j in range(6) for k in range(6)]
    if "bilinear" in families:
        alphas += [(j, Alpha("lin", k)) for j in range(6) for k in range(j, 6)]
    if "norm" in families:
        alphas += [(j, Alpha(kind)) for kind in ("norm", "anorm") for j in range(6)]
        alphas += [(j, Alpha("pnorm", k, m)) for k, m in CROSS_PAIRS for j in range(6)]
    if "area" in families:
        alphas += [(j, Alpha("area", k)) for k in range(6) for j in range(6)]
        alphas += [(j, Alpha("area", k, m)) for k, m in CROSS_PAIRS for j in range(6)]
    out = []
    for r in rows:
        i = dof_index(r, "rows")
        out += [CrossSpec(i, j, a, library_name(i, j, a)) for j, a in alphas]
    return out


def memory_term(dof_rates: Mapping[str | int, Sequence[float]]) -> DampingTerm:
    """D_freq: fluid memory K(t) = Σ_m c_m e^{−λ_m t} per DOF, e.g. ``{'u': [2.0]}``."""
    rates: list[float] = []
    dofs: list[int] = []
    for d, lam in dof_rates.items():
        for lm in lam:
            if not np.isfinite(lm) or lm <= 0:
                raise ConfigError("freq.rates", f"rates must be > 0, got {lm}")
            rates.append(float(lm))
            dofs.append(dof_index(d, "freq.dofs"))
    return DampingTerm("freq", "fluid memory (radiation/wake), force = ∫ K(t−s) ν(s) ds",
                       rates=np.array(rates), state_dofs=np.array(dofs, dtype=np.int64))


def added_mass_term() -> DampingTerm:
    """D_added: Munk-type moments from added mass not captured in M (K_vw, M_uw, N_uv)."""
    bases = [
        Basis("added.K_vw", unit(3, 2), Alpha("lin", 1)),  # K ∝ v w
        Basis("added.M_uw", unit(4, 2), Alpha("lin", 0)),  # M ∝ u w
        Basis("added.N_uv", unit(5, 1), Alpha("lin", 0)),  # N ∝ u v
    ]
    return DampingTerm("added", "velocity-dependent added-mass (Munk) moments not in M", bases)


#: Letters of the added-mass corrections of the ``coriolis`` term and, per correction, its
#: four (row, column, velocity of α, sign) entries: with δA = diag(m_u, m_v, m_w) the
#: Coriolis force ω × (δA v) and the Munk moment v × (δA v) (Fossen's C_A(ν)ν of δA).
CORIOLIS_ENTRIES = {
    "u": ((1, 0, 5, 1.0), (2, 0, 4, -1.0), (4, 0, 2, 1.0), (5, 0, 1, -1.0)),
    "v": ((0, 1, 5, -1.0), (2, 1, 3, 1.0), (3, 1, 2, -1.0), (5, 1, 0, 1.0)),
    "w": ((0, 2, 4, 1.0), (1, 2, 3, -1.0), (3, 2, 1, 1.0), (4, 2, 0, -1.0)),
}


def coriolis_term(dofs: Iterable[str] = ("u", "v", "w")) -> DampingTerm:
    """D_coriolis: the velocity forces of translational added-mass corrections.

    A correction δA = diag(m_u, m_v, m_w) (kg) of the translational added mass acts through
    Fossen's C_A(ν)ν: the Coriolis force ω × (δA v) and the Munk moment v × (δA v), e.g.
    m_u gives Y ∝ u r, Z ∝ −u q, M ∝ u w, N ∝ −u v. Its inertial force δA v̇ is not part
    of it (the regression target keeps the vehicle's M). The term does no work (νᵀDν = 0).
    MuJoCo's Magnus lift ρ V C_M ω × v on an ellipsoid geom is of this form with
    m_u = m_v = m_w = −ρ V C_M, so a MuJoCo plant needs one parameter per axis for it,
    not six bilinear coefficients.

    Parameters
    ----------
    dofs : iterable of str
        Which of u, v, w carry a correction (parameters ``coriolis.m_u`` …).
    """
    bases = []
    for d in dofs:
        if d not in CORIOLIS_ENTRIES:
            raise ConfigError("coriolis", f"{d!r}: the corrections are along u, v or w")
        atoms = []
        for row, col, k, sign in CORIOLIS_ENTRIES[d]:
            # entry (row, col) of D(ν) with α = ν_k: force row += sign · m · ν_k ν_col
            atoms.append((sign * unit(row, col), Alpha("lin", k)))
        (B, alpha), *more = atoms
        bases.append(Basis(f"coriolis.m_{d}", B, alpha, tuple(more)))
    return DampingTerm("coriolis", "Coriolis force and Munk moment of translational added-mass "
                                   "corrections (and MuJoCo's Magnus lift)", bases)


def residual_term(modes: FloatArray | None = None) -> DampingTerm:
    """D_residual = U S(ν) Uᵀ with S = diag(s_k |u_kᵀν|): quadratic drag along mode u_k.

    Parameters
    ----------
    modes : ndarray, shape (6, r), optional
        Columns u_k (normalised here). Default: the two coupled modes surge+heave and
        sway+yaw, which the diagonal terms cannot represent.
    """
    if modes is None:
        modes = np.zeros((6, 2))
        modes[[0, 2], 0] = 1.0
        modes[[1, 5], 1] = 1.0
    U = np.asarray(modes, dtype=float)
    if U.ndim != 2 or U.shape[0] != 6:
        raise ConfigError("residual.modes", f"must be 6×r, got shape {U.shape}")
    U = U / np.linalg.norm(U, axis=0, keepdims=True)
    bases = [Basis(f"residual.s{k + 1}", np.outer(U[:, k], U[:, k]),
                   Alpha("absproj", w=tuple(U[:, k]))) for k in range(U.shape[1])]
    return DampingTerm("residual", "low-rank catch-all for what the named terms miss", bases)
