"""Damping D(ν) as a sum of named terms, each linear in its parameters.

Every scalar parameter θ_j owns a basis matrix B_j (6×6) and a scalar function α_j(ν),
so a static term contributes D_t(ν) = Σ_j θ_j α_j(ν) B_j and the damping force
D_t(ν)ν = Σ_j θ_j α_j(ν) B_j ν. The regressor column of θ_j is therefore α_j(ν) B_j ν
and the whole model is y = Φ(ν) θ with Φ of shape (N, 6, p). A parameter that acts through
several velocity products at once (the Coriolis and Munk forces of an added-mass correction:
one mass, four entries) carries further (B, α) pairs, its "atoms": its column is
Σ_k α_k(ν) B_k ν.

The memory term D_freq replaces ν by filter states z (ż = −λ z + ν, so z is the convolution
of ν with e^{−λt}); its columns are e_i z_{i,m} and its force is Σ_m c_m z_m, the
finite-dimensional form of ∫ K(t−s) ν(s) ds with K(t) = Σ_m c_m e^{−λ_m t}.

All velocities are in Fossen's FRD body frame, relative to the water. Coefficients are stored
positive when dissipative (force on the left-hand side is +D(ν)ν).

The scalar functions α(ν) are in :mod:`dampest_ros.core.physics.alpha`, the term constructors and
the library of candidate terms with their names in :mod:`dampest_ros.core.physics.terms`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.alpha import Alpha, AlphaBank
from dampest_ros.core.physics.rigid_body import DOF_NAMES, ConfigError

FloatArray = NDArray[np.float64]

TERM_KINDS = ("linear", "quadratic", "cross", "freq", "added", "coriolis", "point", "residual")


@dataclass(frozen=True)
class Basis:
    """One scalar parameter: its name, basis matrix B (6×6) and function α(ν), and the
    further (B_k, α_k) pairs of a parameter that acts through several products (``more``):
    its contribution to D(ν) is θ (α(ν) B + Σ_k α_k(ν) B_k)."""

    name: str
    B: FloatArray
    alpha: Alpha = field(default_factory=Alpha)
    more: tuple[tuple[FloatArray, Alpha], ...] = ()

    @property
    def atoms(self) -> list[tuple[FloatArray, Alpha]]:
        """Every (B, α) pair of the parameter, the first one first."""
        return [(self.B, self.alpha), *self.more]

    @property
    def reads(self) -> frozenset[int]:
        """The components of ν (0..5) its column α(ν) B ν (+ …) is a function of: those a
        B_k multiplies and those an α_k reads."""
        return frozenset(int(j) for B, alpha in self.atoms
                         for j in [*np.flatnonzero(np.any(B != 0, axis=0)), *alpha.reads])


def unit(i: int, j: int) -> FloatArray:
    """The basis matrix with a single 1 at row i, column j, shape (6, 6)."""
    B = np.zeros((6, 6))
    B[i, j] = 1.0
    return B


@dataclass
class DampingTerm:
    """A named damping term D_t(ν) = Σ_j θ_j α_j(ν) B_j.

    Parameters
    ----------
    kind : str
        One of :data:`TERM_KINDS`.
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
            for B, alpha in b.atoms:
                D += th * alpha(nu)[:, None, None] * B
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
            # ν_s,b / F_a over the entries of B_j (their pattern; a mode's entries are < 1);
            # the largest over the parameter's atoms
            out[j] = max(alpha.scale(nu_scale)
                         * float(((B != 0) * nu_scale[None, :] / force_scale[:, None]).max())
                         for B, alpha in b.atoms)
        return out

    def project(self, theta: FloatArray) -> FloatArray:
        """Project this term's parameters so that the term is dissipative on its own.

        Linear term: the symmetric part of D_linear onto the PSD cone. Quadratic, point-drag
        and residual terms: negative weights of PSD bases to zero (of a single atom: an
        element's lift or Magnus force, :mod:`.point_lift`, has several, not all PSD, and
        does no work, so its weight keeps its sign). Memory: c_m ≥ 0 (a
        positive kernel is passive). Cross and added-mass terms have indefinite bases: left
        unchanged; their effect is checked on data with :meth:`DampingModel.dissipation`
        (the ``coriolis`` term does no work at all: its D(ν) is skew).
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
        if self.kind in ("quadratic", "point", "residual"):
            psd = np.array([not b.more
                            and np.linalg.eigvalsh(0.5 * (b.B + b.B.T)).min() >= -1e-12
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
        # static atoms (every term but freq: one per (B, α) pair), in θ order; the column of
        # θ_j is the sum of its atoms' columns
        static = [(self._slices[t.kind].start + k, B, alpha) for t in self.terms
                  if t.kind != "freq" for k, b in enumerate(t.bases) for B, alpha in b.atoms]
        self._static_idx = np.array([k for k, _, _ in static], dtype=np.int64)
        self._Bs = np.stack([B for _, B, _ in static]) if static else np.zeros((0, 6, 6))
        self._bank = AlphaBank([alpha for _, _, alpha in static])
        # the atoms whose B_j has two entries in one row (a mode, an element drag) go through
        # a matrix product, ν B_flat[b, a·k + j] = (B_j ν)_a over those k atoms; the others'
        # (the library's single entries) (B_j ν)_a is one product of an entry and ν
        self._dense = np.flatnonzero((np.count_nonzero(self._Bs, axis=2) > 1).any(axis=1))
        self._B_flat = self._Bs[self._dense].transpose(2, 1, 0).reshape(6, -1)
        sparse = np.isin(np.arange(len(self._Bs)), self._dense, invert=True)
        atom, row, col = np.nonzero(self._Bs * sparse[:, None, None])
        self._entries = (atom, row, col, self._Bs[atom, row, col])
        freq = self.term("freq")
        self._freq_idx = (np.arange(self._slices["freq"].start, self._slices["freq"].stop)
                          if freq is not None else np.zeros(0, dtype=np.int64))
        # the entries of Φ that are not zero for every ν, (row, parameter) row-major, and per
        # rank of atom in its parameter (its first, second, … atom) which products add into
        # which entry: within a rank a parameter has at most one atom, so its products go to
        # distinct entries. Products: the sparse entries, then the rows B_j fills of each
        # matrix-product atom (column a · k_dense + k of (B_j ν)_a for every a and k)
        p = max(self.n_params, 1)
        d_atom, d_row = np.nonzero(np.count_nonzero(self._Bs[self._dense], axis=2))
        self._dense_cols = d_row * len(self._dense) + d_atom
        rank = np.array([k for t in self.terms if t.kind != "freq" for b in t.bases
                         for k in range(len(b.atoms))], dtype=np.int64)
        product_rank = np.r_[rank[atom], rank[self._dense[d_atom]]]
        flat = np.r_[row * p + self._static_idx[atom],
                     d_row * p + self._static_idx[self._dense[d_atom]]].astype(np.int64)
        memory = (self.memory_dofs * p + self._freq_idx).astype(np.int64)
        live = np.unique(np.r_[flat, memory])
        self._live_rows, self._live_params = live // p, live % p
        self._adds = [(np.flatnonzero(product_rank == k),
                       np.searchsorted(live, flat[product_rank == k]))
                      for k in range(int(product_rank.max(initial=-1)) + 1)]
        self._memory_entries = np.searchsorted(live, memory)

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
        """Φ(ν) such that D(ν)ν (+ memory force) = Φ θ, shape (N, 6, p): :meth:`scatter` of
        :meth:`regressor_entries` (the same parameters)."""
        return self.scatter(self.regressor_entries(nu, states))

    @property
    def pattern(self) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Row (force, 0..5) and parameter of each entry of Φ that is not zero for every ν,
        shape (L,) each, row-major: what :meth:`regressor_entries` gives."""
        return self._live_rows, self._live_params

    def regressor_entries(self, nu: FloatArray, states: FloatArray | None = None
                          ) -> FloatArray:
        """The entries of :meth:`regressor` that its :attr:`pattern` names, shape (N, L),
        entry by entry in memory (Fortran order): Φ without the zeros (a single-entry
        coefficient fills one force row of six).

        Parameters
        ----------
        nu : ndarray, shape (N, 6)
            Velocity relative to the water, FRD (m/s, rad/s).
        states : ndarray, shape (N, n_states), optional
            Memory states; required when the model has a ``freq`` term.
        """
        nu = np.atleast_2d(np.asarray(nu, dtype=float))
        N = nu.shape[0]
        # formed entry by entry (rows of X), from ν and α by component and function
        X = np.zeros((len(self._live_rows), N))
        if len(self._static_idx):
            atom, _, col, value = self._entries
            alpha = self._bank.rows(nu)
            # (B_j ν)_a α_j(ν): a sparse entry's one product, a matrix-product atom's rows
            products = np.ascontiguousarray(nu.T)[col] * value[:, None] * alpha[atom]
            if len(self._dense):
                dense = ((nu @ self._B_flat).reshape(N, 6, -1)
                         * alpha[self._dense].T[:, None, :]).reshape(N, -1)
                products = np.concatenate([products, dense[:, self._dense_cols].T])
            for take, put in self._adds:
                # entry (a, j) = Σ over the parameter's atoms of α B ν
                X[put] += products[take]
        if len(self._freq_idx):
            if states is None:
                raise ValueError("the freq term needs its memory states")
            # column m: e_{dof_m} z_m
            X[self._memory_entries] = states.T
        return np.asarray(X.T)

    def scatter(self, entries: FloatArray) -> FloatArray:
        """Φ, shape (N, 6, p), from its :attr:`pattern`'s entries, shape (N, L)."""
        Phi = np.zeros((len(entries), 6, self.n_params))
        Phi[:, self._live_rows, self._live_params] = entries
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
        """α(ν) of the static atoms (one per parameter but for multi-product ones), shape
        (N, n_atoms)."""
        return self._bank(nu)

    def alpha_one(self, nu: list[float]) -> FloatArray:
        """α(ν) of the static atoms for one sample ν (6 floats), shape (n_atoms,): the row
        :meth:`alphas` gives, computed without numpy's per-call overhead."""
        return self._bank.one(nu)

    def static_gain(self, theta: FloatArray) -> FloatArray:
        """θ B of the static atoms, flattened: D(ν) = α(ν) K, shape (n_atoms, 36)."""
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
                psd = [not b.more and
                       np.linalg.eigvalsh(0.5 * (b.B + b.B.T)).min() >= -1e-12 and
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
    from scipy import signal  # here: loading scipy.signal costs 0.8 s, most users never need it
    u = np.empty_like(x)
    u[0] = 0.0
    u[1:] = b0 * x[:-1] + b1 * x[1:]
    return np.asarray(signal.lfilter([1.0], [1.0, -a], u), dtype=float)
