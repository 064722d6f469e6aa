"""Damping D(ν) as a sum of named terms, each linear in its parameters.

Every scalar parameter θ_j owns one basis matrix B_j (6×6) and one scalar function α_j(ν),
so a static term contributes D_t(ν) = Σ_j θ_j α_j(ν) B_j and the damping force
D_t(ν)ν = Σ_j θ_j α_j(ν) B_j ν. The regressor column of θ_j is therefore α_j(ν) B_j ν
and the whole model is y = Φ(ν) θ with Φ of shape (N, 6, p).

The memory term D_freq replaces ν by filter states z (ż = −λ z + ν, so z is the convolution
of ν with e^{−λt}); its columns are e_i z_{i,m} and its force is Σ_m c_m z_m, the
finite-dimensional form of ∫ K(t−s) ν(s) ds with K(t) = Σ_m c_m e^{−λ_m t}.

All velocities are in Fossen's FRD body frame, relative to the water. Coefficients are stored
positive when dissipative (force on the left-hand side is +D(ν)ν).

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
=========================  =====================  ==========  ============================

The projected-area family is bluff-body drag with a direction-dependent area: the drag
ρ C A(v̂) ‖v‖ ν_j with the area interpolated by the squared direction cosines,
A(v̂) ≈ Σ_k A_k v_k² / ‖v‖², is Σ_k (ρ C A_k) ν_j v_k² / ‖v‖, linear in the A_k; the three
columns of one ν_j sum to ν_j ‖v‖ (MuJoCo's ellipsoid drag is of this kind).

The bilinear name carries an ``x`` (times) so that it never equals the cross-flow name of the
same letters (Y_{v|r|} is ``Y_vr``, Y_{v r} is ``Y_vxr``); ν_j ν_k and ν_k ν_j are one column,
named with the letters in u..r order. A :class:`CrossSpec` without a name keeps the older
label (α letters without bars, e.g. ``Z_wu`` for Z ← w u); :func:`library` always names its
candidates as above, and a model file stores every name with its row, column and α text, so
both forms read back unchanged.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from dampest_ros.core.rigid_body import DOF_NAMES, FORCE_NAMES, ConfigError

FloatArray = NDArray[np.float64]

TERM_KINDS = ("linear", "quadratic", "cross", "freq", "added", "residual")


def _dof(name: str | int, what: str = "dof") -> int:
    """Index 0..5 of a velocity letter (u..r), a force letter (X..N) or an int."""
    if isinstance(name, int) and 0 <= name < 6:
        return name
    if isinstance(name, str):
        if name in DOF_NAMES:
            return DOF_NAMES.index(name)
        if name in FORCE_NAMES:
            return FORCE_NAMES.index(name)
    raise ConfigError(what, f"unknown degree of freedom {name!r}; use one of {DOF_NAMES}")


@dataclass(frozen=True)
class Alpha:
    """A scalar function α(ν) of the body velocity, from a small library.

    kinds: ``one`` (1), ``abs`` (|ν_i|), ``lin`` (ν_i), ``norm`` (‖[u, v, w]‖, m/s),
    ``anorm`` (‖[p, q, r]‖, rad/s), ``pnorm`` (‖[ν_i, ν_j]‖, the cross-flow speed of a body
    slender along the third axis), ``area`` (ν_i² / ‖v‖ for a linear ν_i, ν_i² / ‖ω‖ for an
    angular one; 0 at rest), ``prod`` (ν_i ν_j), ``absprod`` (|ν_i ν_j|),
    ``absproj`` (|wᵀν| for a unit 6-vector w).
    """

    kind: str = "one"
    i: int = -1
    j: int = -1
    w: tuple[float, ...] = ()

    def __call__(self, nu: FloatArray) -> FloatArray:
        """Evaluate on samples ``nu`` of shape (N, 6); returns shape (N,)."""
        k = self.kind
        if k == "one":
            return np.ones(nu.shape[0])
        if k == "abs":
            return np.abs(nu[:, self.i])
        if k == "lin":
            return nu[:, self.i].copy()
        if k == "norm":
            return np.sqrt(np.einsum("ni,ni->n", nu[:, :3], nu[:, :3]))
        if k == "anorm":
            return np.sqrt(np.einsum("ni,ni->n", nu[:, 3:], nu[:, 3:]))
        if k == "pnorm":
            return np.hypot(nu[:, self.i], nu[:, self.j])
        if k == "area":
            return _area(nu, np.array([self.i]))[:, 0]
        if k == "prod":
            return nu[:, self.i] * nu[:, self.j]
        if k == "absprod":
            return np.abs(nu[:, self.i] * nu[:, self.j])
        if k == "absproj":
            return np.abs(nu @ np.asarray(self.w))
        raise ConfigError("alpha", f"unknown kind {k!r}")

    def scale(self, nu_scale: FloatArray) -> float:
        """Factor c with α(ν_s ⊙ ν') = c α(ν') for velocity scales ν_s, shape (6,).

        Exact for ``one, abs, lin, prod, absprod``; for ``norm`` and ``absproj`` exact when
        the velocities inside α share one scale (the largest is used).
        """
        s = np.asarray(nu_scale, dtype=float)
        k = self.kind
        if k == "one":
            return 1.0
        if k in ("abs", "lin"):
            return float(s[self.i])
        if k in ("prod", "absprod"):
            return float(s[self.i] * s[self.j])
        if k == "pnorm":
            return float(max(s[self.i], s[self.j]))
        if k == "area":
            return float(s[self.i] ** 2 / (s[:3].max() if self.i < 3 else s[3:].max()))
        if k == "norm":
            return float(s[:3].max())
        if k == "anorm":
            return float(s[3:].max())
        if k == "absproj":
            return float(s[np.abs(np.asarray(self.w)) > 0].max())
        raise ConfigError("alpha", f"unknown kind {k!r}")

    def label(self) -> str:
        """Short text form, e.g. ``|r|``, ``u``, ``|U|`` (‖v‖), ``|W|`` (‖ω‖)."""
        n = DOF_NAMES
        return {
            "one": "1",
            "abs": f"|{n[self.i]}|" if self.i >= 0 else "",
            "lin": n[self.i] if self.i >= 0 else "",
            "norm": "|U|",
            "anorm": "|W|",
            "pnorm": f"|{n[self.i]},{n[self.j]}|" if self.i >= 0 else "",
            "area": f"{n[self.i]}^2/{'|U|' if self.i < 3 else '|W|'}" if self.i >= 0 else "",
            "prod": f"{n[self.i]}{n[self.j]}" if self.i >= 0 else "",
            "absprod": f"|{n[self.i]}{n[self.j]}|" if self.i >= 0 else "",
            "absproj": "|w'nu|",
        }[self.kind]

    @classmethod
    def parse(cls, text: str) -> Alpha:
        """Parse ``1``, ``|r|``, ``u``, ``|U|`` (‖v‖), ``|W|`` (‖ω‖), ``|v,w|`` (‖(v, w)‖),
        ``uv``, ``|uv|``."""
        t = text.replace(" ", "")
        if t in ("1", "", "one"):
            return cls("one")
        if t in ("|U|", "norm"):
            return cls("norm")
        if t in ("|W|", "anorm"):
            return cls("anorm")
        if t.endswith(("^2/|U|", "^2/|W|")):
            i = _dof(t[:-6], "alpha")
            if (i < 3) != t.endswith("|U|"):
                raise ConfigError("alpha", f"{text!r}: a linear velocity goes over |U|, an "
                                  "angular one over |W|")
            return cls("area", i)
        if "," in t and t.startswith("|") and t.endswith("|"):
            pair = [_dof(c, "alpha") for c in t.strip("|").split(",")]
            if len(pair) == 2:
                return cls("pnorm", pair[0], pair[1])
        bars = t.startswith("|") and t.endswith("|")
        core = t.strip("|")
        idx = [_dof(c, "alpha") for c in core]
        if len(idx) == 1:
            return cls("abs" if bars else "lin", idx[0])
        if len(idx) == 2:
            return cls("absprod" if bars else "prod", idx[0], idx[1])
        raise ConfigError("alpha", f"cannot parse {text!r}")


class AlphaBank:
    """All α_j of a list of bases evaluated at once: a fixed number of array operations
    whatever p is, so the per-sample cost in the simulator and the RLS stays small.

    Parameters
    ----------
    alphas : sequence of Alpha
    """

    _ONE = 6  # index of the constant column appended to ν

    def __init__(self, alphas: Sequence[Alpha]) -> None:
        p = len(alphas)
        self.i = np.full(p, self._ONE)
        self.j = np.full(p, self._ONE)
        self.absolute = np.zeros(p, dtype=bool)
        self.norm = np.zeros(p, dtype=bool)
        self.anorm = np.zeros(p, dtype=bool)
        self.pnorm = np.zeros(p, dtype=bool)
        self.area = np.zeros(p, dtype=bool)
        self.W = np.zeros((6, p))
        self.proj = np.zeros(p, dtype=bool)
        for k, a in enumerate(alphas):
            if a.kind in ("abs", "lin", "prod", "absprod", "pnorm", "area"):
                self.i[k] = a.i
            if a.kind in ("prod", "absprod", "pnorm"):
                self.j[k] = a.j
            self.absolute[k] = a.kind in ("abs", "absprod", "absproj")
            self.norm[k] = a.kind == "norm"
            self.anorm[k] = a.kind == "anorm"
            self.pnorm[k] = a.kind == "pnorm"
            self.area[k] = a.kind == "area"
            if a.kind == "absproj":
                self.proj[k] = True
                self.W[:, k] = a.w
        self.any_norm = bool(self.norm.any())
        self.any_anorm = bool(self.anorm.any())
        self.any_pnorm = bool(self.pnorm.any())
        self.any_area = bool(self.area.any())
        self.any_proj = bool(self.proj.any())
        self.any_abs = bool(self.absolute.any())

    def __call__(self, nu: FloatArray) -> FloatArray:
        """α for samples ``nu`` (N, 6); returns (N, p)."""
        aug = np.concatenate([nu, np.ones((nu.shape[0], 1))], axis=1)
        # products ν_i ν_j with ν_6 ≡ 1 cover the kinds one, lin and prod
        a = aug[:, self.i] * aug[:, self.j]
        if self.any_pnorm:
            a = np.where(self.pnorm, np.hypot(aug[:, self.i], aug[:, self.j]), a)
        if self.any_area:
            a[:, self.area] = _area(nu, self.i[self.area])
        if self.any_proj:
            a = np.where(self.proj, nu @ self.W, a)
        if self.any_norm:
            speed = np.sqrt(np.einsum("ni,ni->n", nu[:, :3], nu[:, :3]))
            a = np.where(self.norm, speed[:, None], a)
        if self.any_anorm:
            turn = np.sqrt(np.einsum("ni,ni->n", nu[:, 3:], nu[:, 3:]))
            a = np.where(self.anorm, turn[:, None], a)
        if self.any_abs:
            a = np.where(self.absolute, np.abs(a), a)
        return a


def _area(nu: FloatArray, k: NDArray[np.int64]) -> FloatArray:
    """ν_k² / ‖v‖ for linear k, ν_k² / ‖ω‖ for angular k, 0 at rest; shape (N, len(k))."""
    lin = np.sqrt(np.einsum("ni,ni->n", nu[:, :3], nu[:, :3]))
    ang = np.sqrt(np.einsum("ni,ni->n", nu[:, 3:], nu[:, 3:]))
    norm = np.where(k < 3, lin[:, None], ang[:, None])
    # ν_k² / ‖·‖ (≤ ‖·‖, so it goes to 0 with the speed)
    return np.divide(nu[:, k] ** 2, norm, out=np.zeros_like(norm), where=norm > 0)


@dataclass(frozen=True)
class Basis:
    """One scalar parameter: its name, basis matrix B (6×6) and function α(ν)."""

    name: str
    B: FloatArray
    alpha: Alpha = Alpha()


def _unit(i: int, j: int) -> FloatArray:
    B = np.zeros((6, 6))
    B[i, j] = 1.0
    return B


@dataclass
class DampingTerm:
    """A named damping term D_t(ν) = Σ_j θ_j α_j(ν) B_j.

    Parameters
    ----------
    kind : str
        One of ``linear, quadratic, cross, freq, added, residual``.
    meaning : str
        One line of physics, shown in reports.
    bases : list of Basis
        One per scalar parameter (static terms).
    rates : ndarray, shape (n_states,)
        ``freq`` only: decay rates λ_m (1/s) of the filter states.
    state_dofs : ndarray of int, shape (n_states,)
        ``freq`` only: which velocity component drives each state.
    """

    kind: str
    meaning: str
    bases: list[Basis] = field(default_factory=list)
    rates: FloatArray = field(default_factory=lambda: np.zeros(0))
    state_dofs: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    def __post_init__(self) -> None:
        if self.kind not in TERM_KINDS:
            raise ConfigError("terms", f"unknown term kind {self.kind!r}; use one of {TERM_KINDS}")

    @property
    def parameter_names(self) -> list[str]:
        """Names of this term's parameters, in θ order."""
        if self.kind == "freq":
            return [f"freq.{DOF_NAMES[d]}.c{m}" for d, m in self._state_labels()]
        return [b.name for b in self.bases]

    @property
    def n_params(self) -> int:
        """Number of linear parameters p_t."""
        return len(self.rates) if self.kind == "freq" else len(self.bases)

    @property
    def n_states(self) -> int:
        """Number of memory filter states (0 for static terms)."""
        return len(self.rates) if self.kind == "freq" else 0

    def _state_labels(self) -> list[tuple[int, int]]:
        count: dict[int, int] = {}
        labels = []
        for d in self.state_dofs:
            count[int(d)] = count.get(int(d), 0) + 1
            labels.append((int(d), count[int(d)]))
        return labels

    @property
    def rate_names(self) -> list[str]:
        """Names of the memory rates λ (``freq`` only), e.g. ``freq.u.lambda1``."""
        return [f"freq.{DOF_NAMES[d]}.lambda{m}" for d, m in self._state_labels()]

    def matrix(self, nu: FloatArray, theta: FloatArray) -> FloatArray:
        """D_t(ν) = Σ_j θ_j α_j(ν) B_j, shape (N, 6, 6); zero for the memory term."""
        D = np.zeros((nu.shape[0], 6, 6))
        if self.kind == "freq":
            return D
        for th, b in zip(theta, self.bases, strict=True):
            D += th * b.alpha(nu)[:, None, None] * b.B
        return D

    def param_scales(self, nu_scale: FloatArray, force_scale: FloatArray) -> FloatArray:
        """Factor s_j that makes θ_j dimensionless: θ'_j = s_j θ_j, shape (p_t,)."""
        if self.kind == "freq":
            d = self.state_dofs
            return nu_scale[d] / self.rates / force_scale[d]
        out = np.empty(len(self.bases))
        for j, b in enumerate(self.bases):
            # θ_j α_j(ν) (B_j ν)_a = F_a θ'_j α_j(ν') (B_j ν')_a with ν = ν_s ⊙ ν': the scale
            # of α (its homogeneity, not its value at ν_s: ‖ν_s[:3]‖ = √3 v) times
            # ν_s,b / F_a over the entries of B_j (their pattern; a mode's entries are < 1)
            a = b.alpha.scale(nu_scale)
            ratio = (b.B != 0) * nu_scale[None, :] / force_scale[:, None]
            out[j] = a * ratio.max()
        return out

    def project(self, theta: FloatArray) -> FloatArray:
        """Project this term's parameters so that the term is dissipative on its own.

        Linear term: the symmetric part of D_linear onto the PSD cone. Quadratic and residual
        terms: negative weights of PSD bases to zero. Memory: c_m ≥ 0 (a positive kernel
        is passive). Cross and added-mass terms have indefinite bases: left unchanged; their
        effect is checked on data with :meth:`DampingModel.dissipation`.
        """
        theta = np.array(theta, dtype=float)
        if self.kind == "freq":
            return np.maximum(theta, 0.0)
        if self.kind == "linear":
            Bs = np.stack([b.B for b in self.bases])
            D = np.einsum("j,jab->ab", theta, Bs)
            sym = psd_project(0.5 * (D + D.T))
            D_proj = sym + 0.5 * (D - D.T)
            out = np.array([float(np.sum(b.B * D_proj)) for b in self.bases])
            # The bases need not span D_proj (e.g. Y_r without N_v): reading θ back then drops
            # entries and can leave the symmetric part indefinite. Shrink the off-diagonal
            # coefficients by the largest factor s in [0, 1] that keeps it PSD: s = 0 always
            # does (the diagonal of a PSD matrix is ≥ 0), s = 1 when nothing was dropped.
            diag = np.array([bool(np.any(np.diag(b.B))) for b in self.bases])
            out[diag] = np.maximum(out[diag], 0.0)

            def min_eig(s: float) -> float:
                A = np.einsum("j,jab->ab", np.where(diag, out, s * out), Bs)
                return float(np.linalg.eigvalsh(0.5 * (A + A.T)).min())

            if min_eig(1.0) < 0.0:
                # the smallest eigenvalue is concave in s, so {s : min_eig(s) ≥ 0} is [0, s*]
                lo, hi = 0.0, 1.0
                for _ in range(60):
                    mid = 0.5 * (lo + hi)
                    lo, hi = (mid, hi) if min_eig(mid) >= 0.0 else (lo, mid)
                out = np.where(diag, out, lo * out)
            return out
        if self.kind in ("quadratic", "residual"):
            psd = np.array([np.linalg.eigvalsh(0.5 * (b.B + b.B.T)).min() >= -1e-12
                            for b in self.bases])
            theta[psd] = np.maximum(theta[psd], 0.0)
        return theta


def psd_project(S: FloatArray) -> FloatArray:
    """Nearest (Frobenius) positive semi-definite matrix to a symmetric matrix.

    Parameters
    ----------
    S : ndarray, shape (n, n), symmetric

    Returns
    -------
    ndarray, shape (n, n)
    """
    w, V = np.linalg.eigh(0.5 * (S + S.T))
    # clip the negative eigenvalues: V max(Λ, 0) Vᵀ
    return (V * np.maximum(w, 0.0)) @ V.T


# --- term constructors -------------------------------------------------------------------


def linear_term(dofs: Iterable[str | int] = DOF_NAMES,
                off_diagonal: Iterable[tuple[str | int, str | int]] = ()) -> DampingTerm:
    """D_linear: diagonal X_u … N_r plus optional off-diagonal entries (e.g. ('Y', 'r'))."""
    bases = []
    for d in dofs:
        i = _dof(d, "linear.dofs")
        bases.append(Basis(f"{FORCE_NAMES[i]}_{DOF_NAMES[i]}", _unit(i, i)))
    for r, c in off_diagonal:
        i, j = _dof(r, "linear.off_diagonal"), _dof(c, "linear.off_diagonal")
        bases.append(Basis(f"{FORCE_NAMES[i]}_{DOF_NAMES[j]}", _unit(i, j)))
    return DampingTerm("linear", "viscous skin friction and laminar drag, force ∝ ν", bases)


def quadratic_term(dofs: Iterable[str | int] = DOF_NAMES) -> DampingTerm:
    """D_quadratic: Σ_i |ν_i| Q_i with diagonal Q_i; parameters X_uu … N_rr (X_{u|u|}, …)."""
    bases = []
    for d in dofs:
        i = _dof(d, "quadratic.dofs")
        n = DOF_NAMES[i]
        bases.append(Basis(f"{FORCE_NAMES[i]}_{n}{n}", _unit(i, i), Alpha("abs", i)))
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
            return cls(_dof(d["row"], "cross.row"), _dof(d["col"], "cross.col"),
                       Alpha.parse(str(d.get("alpha", "1"))), str(d.get("name", "")))
        except KeyError as exc:
            raise ConfigError(f"cross.{exc.args[0]}", "missing") from None


def cross_term(specs: Sequence[CrossSpec]) -> DampingTerm:
    """D_cross: Σ_k α_k(ν) B_k with single off-diagonal (or diagonal) coupling bases."""
    bases = [Basis(s.label, _unit(s.row, s.col), s.alpha) for s in specs]
    return DampingTerm("cross", "coupling between degrees of freedom from asymmetric flow, "
                       "e.g. sway–yaw", bases)


#: Named families of the term library (see the module docstring for their names).
FAMILIES = ("linear", "crossflow", "bilinear", "norm", "area")


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
        return f"{f}_{n[col]}A{n[alpha.i]}"
    return CrossSpec(row, col, alpha).label


def library(families: Sequence[str] = FAMILIES, rows: Iterable[str | int] = DOF_NAMES
            ) -> list[CrossSpec]:
    """Candidate coefficients of the named families, each a named :class:`CrossSpec`.

    Per force row: ``linear`` ν_j (6), ``crossflow`` ν_j|ν_k| (36, the quadratic X_uu among
    them), ``bilinear`` ν_j ν_k for j ≤ k (21, lift u·w, Magnus-like ω × v products),
    ``norm`` ν_j ‖v‖ and ν_j ‖ω‖ (12) and the cross-flow speeds ν_j ‖(v, w)‖, ν_j ‖(u, w)‖,
    ν_j ‖(u, v)‖, ν_j ‖(q, r)‖, ν_j ‖(p, r)‖, ν_j ‖(p, q)‖ (36), ``area`` ν_j ν_k² / ‖v‖
    and ν_j ν_k² / ‖ω‖ (36). Every column appears once
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
        pairs = ((1, 2), (0, 2), (0, 1), (4, 5), (3, 5), (3, 4))
        alphas += [(j, Alpha("pnorm", k, m)) for k, m in pairs for j in range(6)]
    if "area" in families:
        alphas += [(j, Alpha("area", k)) for k in range(6) for j in range(6)]
    out = []
    for r in rows:
        i = _dof(r, "rows")
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
            dofs.append(_dof(d, "freq.dofs"))
    return DampingTerm("freq", "fluid memory (radiation/wake), force = ∫ K(t−s) ν(s) ds",
                       rates=np.array(rates), state_dofs=np.array(dofs, dtype=np.int64))


def added_mass_term() -> DampingTerm:
    """D_added: Munk-type moments from added mass not captured in M (K_vw, M_uw, N_uv)."""
    bases = [
        Basis("added.K_vw", _unit(3, 2), Alpha("lin", 1)),  # K ∝ v w
        Basis("added.M_uw", _unit(4, 2), Alpha("lin", 0)),  # M ∝ u w
        Basis("added.N_uv", _unit(5, 1), Alpha("lin", 0)),  # N ∝ u v
    ]
    return DampingTerm("added", "velocity-dependent added-mass (Munk) moments not in M", bases)


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


# --- the model -----------------------------------------------------------------------------


class DampingModel:
    """D(ν) as the ordered list of named terms; θ is their parameters stacked in order.

    Parameters
    ----------
    terms : sequence of DampingTerm
        At most one term of each kind.
    """

    def __init__(self, terms: Sequence[DampingTerm]) -> None:
        kinds = [t.kind for t in terms]
        if len(set(kinds)) != len(kinds):
            raise ConfigError("terms", f"each kind may appear once, got {kinds}")
        self.terms = list(terms)
        names = self.parameter_names
        if len(set(names)) != len(names):
            raise ConfigError("terms", "duplicate parameter names")
        self._slices: dict[str, slice] = {}
        start = 0
        for t in self.terms:
            self._slices[t.kind] = slice(start, start + t.n_params)
            start += t.n_params
        # static columns (every term but freq), in θ order
        static = [(self._slices[t.kind].start + k, b) for t in self.terms if t.kind != "freq"
                  for k, b in enumerate(t.bases)]
        self._static_idx = np.array([k for k, _ in static], dtype=np.int64)
        self._Bs = np.stack([b.B for _, b in static]) if static else np.zeros((0, 6, 6))
        self._bank = AlphaBank([b.alpha for _, b in static])
        freq = self.term("freq")
        self._freq_idx = (np.arange(self._slices["freq"].start, self._slices["freq"].stop)
                          if freq is not None else np.zeros(0, dtype=np.int64))

    @property
    def parameter_names(self) -> list[str]:
        """All parameter names in θ order."""
        return [n for t in self.terms for n in t.parameter_names]

    @property
    def n_params(self) -> int:
        """p, the length of θ."""
        return sum(t.n_params for t in self.terms)

    @property
    def kinds(self) -> list[str]:
        """Kinds of the terms, in order."""
        return [t.kind for t in self.terms]

    def term(self, kind: str) -> DampingTerm | None:
        """The term of a kind, or None."""
        return next((t for t in self.terms if t.kind == kind), None)

    def slice(self, kind: str) -> slice:
        """The slice of θ that belongs to a term kind."""
        return self._slices[kind]

    # memory states ---------------------------------------------------------------------

    @property
    def memory_rates(self) -> FloatArray:
        """λ of every memory state, shape (n_states,)."""
        t = self.term("freq")
        return t.rates if t is not None else np.zeros(0)

    @property
    def memory_dofs(self) -> NDArray[np.int64]:
        """Driving velocity index of every memory state, shape (n_states,)."""
        t = self.term("freq")
        return t.state_dofs if t is not None else np.zeros(0, dtype=np.int64)

    def memory_derivative(self, z: FloatArray, nu: FloatArray) -> FloatArray:
        """ż = −λ z + ν_dof for the memory states, shape like ``z``."""
        return -self.memory_rates * z + nu[..., self.memory_dofs]

    def memory_states(self, t: FloatArray, nu: FloatArray) -> FloatArray:
        """Memory states along a uniformly sampled velocity series (z(0) = 0).

        Discretises ż = −λz + ν exactly for ν linear between samples (first-order hold).

        Parameters
        ----------
        t : ndarray, shape (N,)
            Uniform sample times (s).
        nu : ndarray, shape (N, 6)

        Returns
        -------
        ndarray, shape (N, n_states)
        """
        return filter_memory(t, nu[:, self.memory_dofs], self.memory_rates)

    # regression ---------------------------------------------------------------------------

    def regressor(self, nu: FloatArray, states: FloatArray | None = None) -> FloatArray:
        """Φ(ν) such that D(ν)ν (+ memory force) = Φ θ.

        Parameters
        ----------
        nu : ndarray, shape (N, 6)
            Velocity relative to the water, FRD (m/s, rad/s).
        states : ndarray, shape (N, n_states), optional
            Memory states; required when the model has a ``freq`` term.

        Returns
        -------
        ndarray, shape (N, 6, p)
        """
        nu = np.atleast_2d(np.asarray(nu, dtype=float))
        N = nu.shape[0]
        Phi = np.empty((N, 6, self.n_params))
        if len(self._static_idx):
            # column j: α_j(ν) B_j ν
            Bnu = np.einsum("jab,nb->naj", self._Bs, nu)
            Phi[:, :, self._static_idx] = Bnu * self._bank(nu)[:, None, :]
        if len(self._freq_idx):
            if states is None:
                raise ValueError("the freq term needs its memory states")
            # column m: e_{dof_m} z_m
            Phi[:, :, self._freq_idx] = 0.0
            Phi[:, self.memory_dofs, self._freq_idx] = states
        return Phi

    def force(self, nu: FloatArray, theta: FloatArray,
              states: FloatArray | None = None) -> FloatArray:
        """Damping force D(ν)ν + Σ c_m z_m, shape (N, 6).

        Evaluated as (Σ_j α_j(ν) θ_j B_j) ν, without forming Φ: cheap for one sample.
        """
        nu = np.atleast_2d(np.asarray(nu, dtype=float))
        # D(ν) = Σ_j α_j(ν) θ_j B_j, then D(ν) ν
        D = (self.alphas(nu) @ self.static_gain(theta)).reshape(-1, 6, 6)
        f = np.einsum("nab,nb->na", D, nu)
        if len(self._freq_idx):
            if states is None:
                raise ValueError("the freq term needs its memory states")
            np.add.at(f.T, self.memory_dofs, (states * theta[self._freq_idx]).T)
        return f

    def alphas(self, nu: FloatArray) -> FloatArray:
        """α_j(ν) of the static parameters, shape (N, p_static)."""
        return self._bank(nu)

    def static_gain(self, theta: FloatArray) -> FloatArray:
        """θ_j B_j of the static parameters, flattened: D(ν) = α(ν) K, shape (p_static, 36)."""
        return (theta[self._static_idx, None, None] * self._Bs).reshape(-1, 36)

    def memory_gain(self, theta: FloatArray) -> FloatArray:
        """c_m of the memory states (θ entries of the freq term), shape (n_states,)."""
        return theta[self._freq_idx]

    def term_forces(self, nu: FloatArray, theta: FloatArray,
                    states: FloatArray | None = None) -> dict[str, FloatArray]:
        """Force of each term separately, computed from its matrix (not the regressor)."""
        nu = np.atleast_2d(np.asarray(nu, dtype=float))
        out: dict[str, FloatArray] = {}
        for t in self.terms:
            th = theta[self.slice(t.kind)]
            if t.kind == "freq":
                if states is None:
                    raise ValueError("the freq term needs its memory states")
                f = np.zeros((nu.shape[0], 6))
                np.add.at(f.T, t.state_dofs, (states * th).T)
                out[t.kind] = f
            else:
                out[t.kind] = np.einsum("nab,nb->na", t.matrix(nu, th), nu)
        return out

    def matrix(self, nu: FloatArray, theta: FloatArray) -> FloatArray:
        """Static D(ν) (all terms but memory), shape (N, 6, 6)."""
        nu = np.atleast_2d(np.asarray(nu, dtype=float))
        D = np.zeros((nu.shape[0], 6, 6))
        for t in self.terms:
            D += t.matrix(nu, theta[self.slice(t.kind)])
        return D

    def dissipation(self, nu: FloatArray, theta: FloatArray) -> FloatArray:
        """Power dissipated by the static terms, νᵀD(ν)ν (W), shape (N,)."""
        nu = np.atleast_2d(np.asarray(nu, dtype=float))
        return np.einsum("na,nab,nb->n", nu, self.matrix(nu, theta), nu)

    def project(self, theta: FloatArray) -> FloatArray:
        """θ with every term projected onto its dissipative set (see DampingTerm.project)."""
        out = np.array(theta, dtype=float)
        for t in self.terms:
            s = self.slice(t.kind)
            out[s] = t.project(out[s])
        return out

    def lower_bounds(self) -> FloatArray:
        """Physical lower bounds: 0 for the weights of PSD bases and memory gains, else −∞."""
        lo = np.full(self.n_params, -np.inf)
        for t in self.terms:
            s = self.slice(t.kind)
            if t.kind == "freq":
                lo[s] = 0.0
            else:
                psd = [np.linalg.eigvalsh(0.5 * (b.B + b.B.T)).min() >= -1e-12 and
                       b.alpha.kind in ("one", "abs", "absprod", "absproj", "norm", "anorm",
                                        "pnorm")
                       for b in t.bases]
                lo[s] = np.where(psd, 0.0, -np.inf)
        return lo

    def param_scales(self, nu_scale: FloatArray, force_scale: FloatArray) -> FloatArray:
        """Per-parameter factor s with θ' = s θ dimensionless, shape (p,)."""
        return np.concatenate([t.param_scales(nu_scale, force_scale) for t in self.terms]) \
            if self.terms else np.zeros(0)

    def theta_from_dict(self, values: dict[str, float], default: float = 0.0) -> FloatArray:
        """θ from a name → value mapping; names not in the model raise ConfigError."""
        names = self.parameter_names
        unknown = set(values) - set(names) - set(self.term_rate_names())
        if unknown:
            raise ConfigError("theta", f"unknown parameter names {sorted(unknown)}")
        return np.array([float(values.get(n, default)) for n in names])

    def term_rate_names(self) -> list[str]:
        """Names of the memory rates (not part of θ; fixed inside the freq term)."""
        t = self.term("freq")
        return t.rate_names if t is not None else []


def filter_memory(t: FloatArray, x: FloatArray, rates: FloatArray) -> FloatArray:
    """Exact first-order-hold discretisation of ż_k = −λ_k z_k + x_k on a uniform grid.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Uniform sample times (s).
    x : ndarray, shape (N, K)
        Driving signals.
    rates : ndarray, shape (K,)
        λ_k (1/s).

    Returns
    -------
    ndarray, shape (N, K)
        z with z(t_0) = 0.
    """
    N, K = x.shape
    out = np.zeros((N, K))
    if N < 2 or K == 0:
        return out
    h = float(t[1] - t[0])
    for k in range(K):
        lam = float(rates[k])
        a = np.exp(-lam * h)
        # For x linear on [t_n, t_{n+1}]: z_{n+1} = a z_n + b0 x_n + b1 x_{n+1}
        b1 = (lam * h - 1.0 + a) / (lam * lam * h)
        b0 = (1.0 - a) / lam - b1
        out[:, k] = _fo_hold(x[:, k], a, b0, b1)
    return out


def _fo_hold(x: FloatArray, a: float, b0: float, b1: float) -> FloatArray:
    # z_{n+1} = a z_n + b0 x_n + b1 x_{n+1}, z_0 = 0, as one IIR filter on the input
    u = np.empty_like(x)
    u[0] = 0.0
    u[1:] = b0 * x[:-1] + b1 * x[1:]
    return np.asarray(signal.lfilter([1.0], [1.0, -a], u), dtype=float)
