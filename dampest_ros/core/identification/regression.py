"""The regression form of identification and its sufficient statistics.

Per sample n (FRD): y_n = τ_n − M ν̇_n − C(ν_n)ν_n − g(η_n) = Φ(ν_n) θ + e_n (:func:`target`,
:meth:`DampingModel.regressor`), formed in chunks of samples with the parallel low-pass of y
and Φ (:func:`iter_regression`), and reduced to normal equations per degree of freedom i and
cross-validation fold f (:func:`accumulate`): A_{f,i} = Σ Φ_iᵀ Φ_i, b_{f,i} = Σ Φ_iᵀ y_i,
c_{f,i} = Σ y_i². Memory does not grow with the length of the data; the statistics of several
logs add up (:mod:`dampest_ros.core.identification.pool`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.identification.cv_budget import guarded_folds
from dampest_ros.core.physics.alpha import Alpha
from dampest_ros.core.physics.damping import Basis, DampingModel, DampingTerm
from dampest_ros.core.physics.frames import matrix_from_euler
from dampest_ros.core.physics.rigid_body import RigidBody
from dampest_ros.core.signals.preprocess import zero_phase
from dampest_ros.core.signals.samples import CHUNK, Samples

FloatArray = NDArray[np.float64]


def target(samples: Samples, body: RigidBody, index: slice | None = None) -> FloatArray:
    """y = τ − M ν̇ − C(ν)ν − g(η), the force the damping must explain, shape (N, 6).

    M and C_A act as the vehicle's ``added_mass_terms`` say (:attr:`RigidBody.M_inertial`,
    :meth:`RigidBody.coriolis_force`)."""
    sl = index if index is not None else slice(None)
    nu, nu_dot = samples.nu[sl], samples.nu_dot[sl]
    R = matrix_from_euler(samples.euler[sl])
    # y = τ − M ν̇ − C(ν)ν − g(η)
    return np.asarray(samples.tau[sl] - nu_dot @ body.M_inertial.T - body.coriolis_force(nu)
                      - body.restoring(R), dtype=float)


def memory_states(samples: Samples, model: DampingModel) -> FloatArray:
    """Memory filter states of the model along every segment, shape (N, n_states)."""
    out = np.zeros((len(samples), len(model.memory_rates)))
    if out.shape[1]:
        for sl in samples.segments():
            out[sl] = model.memory_states(samples.t[sl], samples.nu[sl])
    return out


def iter_entries(samples: Samples, model: DampingModel, body: RigidBody,
                 chunk: int = CHUNK, cutoff: float = 0.0, margin: float = 5.0,
                 offset: FloatArray | None = None, decimate: bool = False,
                 entries: Callable[[FloatArray, FloatArray | None], FloatArray] | None = None
                 ) -> Iterator[tuple[slice | NDArray[np.int64], FloatArray, FloatArray]]:
    """Yield (rows, X (n, L), y (n, 6)) over chunks of at most ``chunk`` samples, X the
    entries of Φ its model's pattern names (:meth:`DampingModel.regressor_entries`): what
    :func:`iter_regression` yields, without Φ's zeros.

    With ``cutoff`` > 0 both y and every column of X are low-passed (zero phase) along time
    within each segment: "parallel filtering". Since θ is constant, LP(y) = LP(Φ) θ holds
    exactly however nonlinear Φ is, whereas filtering ν before forming |ν|ν does not. Chunks
    are filtered with ``margin`` seconds of neighbouring data on both sides, so memory stays
    flat while the result equals filtering whole segments (to the filter's decay).

    ``offset`` (6,) is added to ν first: the data as a sensor bias would have made them.

    ``entries(ν, z)`` replaces ``model.regressor_entries`` (the model still gives the memory
    states z): any columns, shape (n, L), e.g. features shared by every row.

    With ``decimate`` (and ``cutoff`` > 0) only every k-th sample is yielded, k the largest
    step that keeps four samples per period of the cutoff: the low-passed signals carry no
    more information than that, and the normal equations cost k times less. Rows are then
    global sample indices, every k-th from each segment's first (the same whatever the
    chunking and whatever segments precede).

    A static model's entries are kept per parameter for the next pass over the same ν
    (:class:`_KeptEntries`): a parameter's entries are the same whatever model holds it. A
    pass with one component of ν offset takes those of the parameters that do not read it.
    """
    settings = (chunk, cutoff, margin, decimate)
    static = entries is None and not len(model.memory_rates)
    if offset is not None:
        shifted = Samples(samples.t, samples.nu + offset, samples.nu_dot, samples.tau,
                          samples.euler, samples.depth, samples.segment)
        axis = np.flatnonzero(offset)
        if static and len(axis) == 1 and _KEPT and _KEPT[0].holds(samples, settings):
            yield from _KEPT[0].entries(shifted, model, body, int(axis[0]))
            return
        samples = shifted
    elif static:
        kept = _kept_entries(samples, settings)
        if kept.fits(model):
            yield from kept.entries(samples, model, body)
            return
    z = memory_states(samples, model)
    has_z = z.shape[1] > 0

    def columns(ext: slice) -> FloatArray:
        return (entries or model.regressor_entries)(samples.nu[ext], z[ext] if has_z else None)

    yield from _chunks(samples, body, columns, *settings)


def _chunks(samples: Samples, body: RigidBody, columns: Callable[[slice], FloatArray],
            chunk: int, cutoff: float, margin: float, decimate: bool, targets: bool = True
            ) -> Iterator[tuple[slice | NDArray[np.int64], FloatArray, FloatArray]]:
    """:func:`iter_entries` of the ``columns`` of each extended chunk (a slice of the samples;
    shape (n, L)); without ``targets``, y of shape (n, 0)."""
    pad = round(margin * samples.rate) if cutoff > 0 else 0
    step = decimation_step(samples, cutoff, decimate)
    for seg in samples.segments():
        s0, s1 = seg.start or 0, seg.stop or 0
        for start in range(s0, s1, chunk):
            stop = min(start + chunk, s1)
            a, b = max(s0, start - pad), min(s1, stop + pad)
            ext = slice(a, b)
            X = columns(ext)
            y = target(samples, body, ext) if targets else np.zeros((b - a, 0))
            if cutoff > 0:
                X = zero_phase(X, samples.rate, cutoff)
                y = zero_phase(y, samples.rate, cutoff)
            # sample by sample in memory (as the low-pass gives them), whatever ``columns``
            # gave: the sums over samples below run in one order
            X = np.ascontiguousarray(X)
            if step > 1:
                # every k-th sample counted from the segment's first: a segment gives the
                # same rows whatever comes before it (a log pooled with others included)
                rows = np.arange(start + (s0 - start) % step, stop, step)
                yield rows, X[rows - a], y[rows - a]
            else:
                core = slice(start - a, stop - a)
                yield slice(start, stop), X[core], y[core]


#: Most bytes of entries :class:`_KeptEntries` holds: a 600 s log's at 50 Hz, decimated for
#: a 2 Hz cutoff, take 38 kB per entry.
ENTRIES_KEPT = 96e6


def decimation_step(samples: Samples, cutoff: float, decimate: bool) -> int:
    """The decimation step of :func:`iter_entries`: four samples per period of the cutoff."""
    return max(1, int(samples.rate / (4.0 * cutoff))) if decimate and cutoff > 0 else 1


def _static_bases(model: DampingModel) -> list[Basis]:
    """The bases of the static parameters, in θ order."""
    return [b for t in model.terms if t.kind != "freq" for b in t.bases]


def _proj_count(bases: list[Basis]) -> int:
    """How many |wᵀν| α the bases' atoms have (the columns of one matrix product in their
    :class:`AlphaBank`)."""
    return sum(alpha.kind == "absproj" for b in bases for _, alpha in b.atoms)


#: What a parameter's entries of Φ are a function of ν of: its atoms (B, α), and whether its
#: model has a single |wᵀν| α (:func:`_proj_count`): a matrix product of one column goes to
#: BLAS's matrix-vector routine, whose sums round otherwise than the matrix-matrix one's.
_Key = tuple[tuple[tuple[bytes, Alpha], ...], bool]


@dataclass
class _KeptEntries:
    """The low-passed entries of Φ of the parameters of the last passes over one ν (the same
    t, segments and chunking), chunk by chunk: the structure searches and the fit form the
    normal equations of models that share most of their parameters, on the same samples.

    A parameter's entries are computed alike whatever model holds it (products and sums of
    its own atoms; the α of each, :class:`AlphaBank`, and the low-pass act column by column,
    a matrix product of several columns too), so they are those a pass over the model would
    give, to the bit.

    Attributes
    ----------
    rows : int
        Rows each entry has over all chunks.
    columns : dict
        :data:`_Key` of a parameter → its entries per chunk, shape (n, r) each, r the rows of
        Φ it fills (in order).
    size : int
        Bytes held.
    target : tuple
        τ, ν̇, attitude and body of the last pass's samples (the same objects), whose
        low-passed target y per chunk ``y`` is (with each chunk's rows, ``chunk_rows``).
    """

    nu: FloatArray
    t: FloatArray
    segment: NDArray[np.int64]
    settings: tuple[int, float, float, bool]
    rows: int
    columns: dict[_Key, list[FloatArray]] = field(default_factory=dict)
    size: int = 0
    target: tuple[object, ...] = ()
    y: list[FloatArray] = field(default_factory=list)
    chunk_rows: list[slice | NDArray[np.int64]] = field(default_factory=list)

    def keys(self, model: DampingModel) -> list[_Key]:
        """The :data:`_Key` of each static parameter of ``model``, in θ order."""
        bases = _static_bases(model)
        alone = _proj_count(bases) == 1
        return [(tuple((B.tobytes(), alpha) for B, alpha in b.atoms), alone) for b in bases]

    def fits(self, model: DampingModel) -> bool:
        """Whether the entries of the static ``model`` that are not kept fit in
        :data:`ENTRIES_KEPT`."""
        fill = np.bincount(model.pattern[1], minlength=model.n_params)
        new = sum(int(fill[j]) for j, k in enumerate(self.keys(model)) if k not in self.columns)
        return self.size + 8 * self.rows * new <= ENTRIES_KEPT

    def holds(self, samples: Samples, settings: tuple[int, float, float, bool]) -> bool:
        """Whether these are the entries of ``samples``' ν (the same arrays) for these
        settings of :func:`iter_entries` (chunk, cutoff, margin, decimate)."""
        return (self.nu is samples.nu and self.t is samples.t
                and self.segment is samples.segment and self.settings == settings)

    def entries(self, samples: Samples, model: DampingModel, body: RigidBody,
                shifted: int | None = None
                ) -> Iterator[tuple[slice | NDArray[np.int64], FloatArray, FloatArray]]:
        """:func:`iter_entries` of the static ``model`` on ``samples``, the entries of its
        parameters that are not kept computed (in a model of those alone) and kept.

        ``samples`` hold the ν of these entries, or with one component, ``shifted``, offset:
        then the parameters whose column does not read it (:attr:`Basis.reads`) take their
        kept entries (ν's other components are the same numbers) and the others are computed
        and not kept."""
        keys = self.keys(model)
        missing: dict[_Key, Basis] = {}
        for k, b in zip(keys, _static_bases(model), strict=True):
            if k not in self.columns or shifted in b.reads:
                missing.setdefault(k, b)
        new = self._new_model(model, list(missing.values()))
        keep = {} if shifted is not None else missing
        for k in keep:
            self.columns[k] = []
        # the target of the last pass's samples is these samples' (τ, ν̇, attitude, body)
        sources = (samples.tau, samples.nu_dot, samples.euler, body)
        known = shifted is None and len(self.target) == 4 and all(
            a is b for a, b in zip(self.target, sources, strict=True))
        # each model's entries parameter by parameter (a stable sort of the row-major pattern
        # by parameter), and back
        by_new = np.argsort(new.pattern[1], kind="stable")
        cuts = np.searchsorted(new.pattern[1][by_new], np.arange(new.n_params + 1))
        index = [new.parameter_names.index(b.name) for b in missing.values()]
        back = np.argsort(np.argsort(model.pattern[1], kind="stable"))
        chunks: Iterable[tuple[slice | NDArray[np.int64], FloatArray, FloatArray]] = (
            zip(self.chunk_rows, (np.zeros((len(y), 0)) for y in self.y), self.y, strict=True)
            if known and not missing else
            _chunks(samples, body, lambda ext: new.regressor_entries(samples.nu[ext]),
                    *self.settings, targets=not known))
        done, ys, chunk_rows = False, [], []
        try:
            for c, (rows, X, y) in enumerate(chunks):
                fresh = {k: X[:, by_new[cuts[j]:cuts[j + 1]]]
                         for j, k in zip(index, missing, strict=True)}
                for k in keep:
                    self.columns[k].append(fresh[k])
                    self.size += fresh[k].nbytes
                ys.append(self.y[c] if known else y)
                chunk_rows.append(rows)
                by_parameter = [fresh[k] if k in fresh else self.columns[k][c] for k in keys]
                yield rows, np.concatenate([X[:, :0], *by_parameter], axis=1)[:, back], ys[c]
            done = True
            if shifted is None:
                self.target, self.y, self.chunk_rows = sources, ys, chunk_rows
        finally:
            if not done:  # a pass left before its end: its new entries are not whole
                for k in keep:
                    self.size -= sum(x.nbytes for x in self.columns.pop(k))

    @staticmethod
    def _new_model(model: DampingModel, bases: list[Basis]) -> DampingModel:
        """The static model of ``bases`` (of ``model``), their |wᵀν| α formed as in
        ``model``: one of its others joins a single one when it has several."""
        ids = {id(b) for b in bases}
        proj = [b for b in _static_bases(model) if _proj_count([b])]
        if _proj_count(bases) == 1 and _proj_count(proj) > 1:
            ids.add(next(id(b) for b in proj if id(b) not in ids))
        return DampingModel([DampingTerm(t.kind, t.meaning, kept) for t in model.terms
                             if (kept := [b for b in t.bases if id(b) in ids])])


#: The entries kept of the last ν (:func:`_kept_entries`).
_KEPT: list[_KeptEntries] = []


def _kept_entries(samples: Samples, settings: tuple[int, float, float, bool]) -> _KeptEntries:
    """The entries kept of ``samples``' ν (the same arrays) for these settings of
    :func:`iter_entries` (chunk, cutoff, margin, decimate); none kept (of other ν
    forgotten) if they are new."""
    if _KEPT and _KEPT[0].holds(samples, settings):
        return _KEPT[0]
    step = decimation_step(samples, settings[1], settings[3])
    # every step-th sample of each segment, from its first
    rows = sum(-(-((sl.stop or 0) - (sl.start or 0)) // step) for sl in samples.segments())
    _KEPT[:] = [_KeptEntries(samples.nu, samples.t, samples.segment, settings, rows)]
    return _KEPT[0]


def iter_regression(samples: Samples, model: DampingModel, body: RigidBody,
                    chunk: int = CHUNK, cutoff: float = 0.0, margin: float = 5.0,
                    offset: FloatArray | None = None, decimate: bool = False
                    ) -> Iterator[tuple[slice | NDArray[np.int64], FloatArray, FloatArray]]:
    """Yield (rows, Φ (n, 6, p), y (n, 6)) over chunks of at most ``chunk`` samples: the
    entries of :func:`iter_entries` (the same arguments) in their places of Φ."""
    for rows, X, y in iter_entries(samples, model, body, chunk, cutoff, margin, offset,
                                   decimate):
        yield rows, model.scatter(X), y


def block_index(samples: Samples, block: float) -> NDArray[np.int64]:
    """Index 0..B−1 of the ``block``-second block of every sample, shape (N,); blocks are
    counted from the first sample of each segment, so a block never spans two segments and
    a log's blocks are the same whatever logs it is pooled with."""
    block_of = np.zeros(len(samples), dtype=np.int64)
    for sl in samples.segments():
        t = samples.t[sl]
        block_of[sl] = np.floor((t - t[0]) / block)
    block_of += samples.segment * (int(block_of.max(initial=0)) + 1)
    return np.unique(block_of, return_inverse=True)[1].astype(np.int64)


@dataclass
class BlockEquations:
    """Per-block, per-DOF normal equations: the robust covariance's block scores at any θ
    and weights (:meth:`scores`) without another pass over the samples.

    Attributes
    ----------
    G : ndarray, shape (B, 6, p, p)
        Σ_{n ∈ b} Φ_niᵀ Φ_ni per block b and DOF i.
    h : ndarray, shape (B, 6, p)
        Σ_{n ∈ b} Φ_niᵀ y_ni.
    length : float
        Block length (s; :func:`block_index`).
    """

    G: FloatArray
    h: FloatArray
    length: float

    def scores(self, theta: FloatArray, weights: FloatArray, free: NDArray[np.bool_]
               ) -> FloatArray:
        """Weighted score of every block over the ``free`` parameters, shape (B, p_free)."""
        # s_b = Σ_i w_i Φ_biᵀ (y_bi − Φ_bi θ) = Σ_i w_i (h_bi − G_bi θ)
        s = np.einsum("i,bip->bp", weights, self.h - self.G @ theta)
        return np.asarray(s[:, free])

    @staticmethod
    def join(parts: list[BlockEquations]) -> BlockEquations:
        """The blocks of several parts of the samples (disjoint blocks), in order."""
        return BlockEquations(np.concatenate([x.G for x in parts]),
                              np.concatenate([x.h for x in parts]), parts[0].length)


@dataclass
class NormalEquations:
    """Per-fold, per-DOF sufficient statistics of the regression.

    Attributes
    ----------
    A : ndarray, shape (F, 6, p, p)
    b : ndarray, shape (F, 6, p)
    c : ndarray, shape (F, 6)
        Σ y².
    n : ndarray, shape (F,)
        Samples per fold.
    blocks : BlockEquations or None
        The same per block of the robust covariance, when asked for (:func:`accumulate`).
    """

    A: FloatArray
    b: FloatArray
    c: FloatArray
    n: FloatArray
    blocks: BlockEquations | None = None

    def total(self, weights: FloatArray, exclude: int | None = None
              ) -> tuple[FloatArray, FloatArray, float]:
        """Σ over folds (but ``exclude``) and DOFs of w_i A, w_i b, w_i c."""
        keep = np.ones(len(self.n), dtype=bool)
        if exclude is not None:
            keep[exclude] = False
        A = np.einsum("i,fipq->pq", weights, self.A[keep])
        b = np.einsum("i,fip->p", weights, self.b[keep])
        return A, b, float(np.einsum("i,fi->", weights, self.c[keep]))

    def rss(self, theta: FloatArray, fold: int | None = None) -> FloatArray:
        """Residual sum of squares per DOF, Σ (y − Φθ)², shape (6,)."""
        sel = slice(None) if fold is None else slice(fold, fold + 1)
        A, b, c = self.A[sel].sum(0), self.b[sel].sum(0), self.c[sel].sum(0)
        # ‖y − Φθ‖² = yᵀy − 2 θᵀΦᵀy + θᵀΦᵀΦθ (≥ 0; rounding can dip below for exact fits)
        return np.maximum(c - 2 * b @ theta + np.einsum("ipq,p,q->i", A, theta, theta), 0.0)


def fold_index(n: int, folds: int) -> NDArray[np.int64]:
    """The contiguous time fold (0..folds−1) of each of n samples, shape (n,)."""
    return np.minimum((np.arange(n) * folds) // max(n, 1), folds - 1)


def accumulate(samples: Samples, model: DampingModel, body: RigidBody, folds: int = 5,
               chunk: int = CHUNK, cutoff: float = 0.0, guard: int = 0, block: float = 0.0
               ) -> NormalEquations:
    """Accumulate :class:`NormalEquations` over contiguous time folds in chunks.

    Parameters
    ----------
    samples : Samples
    model : DampingModel
    body : RigidBody
    folds : int
        Number of contiguous blocks for cross-validation.
    chunk : int
        Samples per chunk (memory ∝ chunk · 6 · p).
    cutoff : float
        Parallel low-pass of y and Φ (Hz); 0: none.
    guard : int
        Samples on each side of a boundary between folds that belong to none
        (:func:`cv_budget.guarded_folds`).
    block : float
        With ``block`` > 0 (s), also the :class:`BlockEquations` of blocks of that length
        (every sample, guards included; memory B · 6 · p² floats), from the same products.
    """
    p, N = model.n_params, len(samples)
    fold_of = guarded_folds(N, folds, guard) if guard else fold_index(N, folds)
    A = np.zeros((folds, 6, p, p))
    b = np.zeros((folds, 6, p))
    c = np.zeros((folds, 6))
    n = np.zeros(folds)
    block_of = block_index(samples, block) if block > 0 else np.zeros(N, dtype=np.int64)
    B = int(block_of.max(initial=-1)) + 1 if block > 0 else 0
    G, h = np.zeros((B, 6, p, p)), np.zeros((B, 6, p))
    width = max(B, 1)  # cells per fold
    # each row's entries of Φ (a slice of the row-major pattern) and their parameters
    rows, params = model.pattern
    bounds = np.searchsorted(rows, np.arange(7))
    per_row = [(i, slice(bounds[i], bounds[i + 1]), params[bounds[i]:bounds[i + 1]])
               for i in range(6) if bounds[i + 1] > bounds[i]]
    for sl, X, y in iter_entries(samples, model, body, chunk, cutoff, decimate=True):
        # a cell: the rows of one fold (−1: a guard) and one block
        cell = (fold_of[sl] + 1) * width + block_of[sl]
        for key in np.unique(cell):
            f, k = divmod(int(key), width)
            if f == 0 and not B:  # a guard, and no blocks asked for
                continue
            m = cell == key
            P, Y = X[m], y[m]
            for i, entries, cols in per_row:
                # per DOF i, over its entries: ΦᵢᵀΦᵢ, Φᵢᵀyᵢ (einsum sums each product over the
                # samples in their order, as over all of Φ: the same statistics to the bit)
                gram = np.einsum("np,nq->pq", P[:, entries], P[:, entries])
                moment = np.einsum("np,n->p", P[:, entries], Y[:, i])
                square = np.ix_(cols, cols)
                if B:
                    G[k, i][square] += gram
                    h[k, i, cols] += moment
                if f:
                    A[f - 1, i][square] += gram
                    b[f - 1, i, cols] += moment
            if f:
                # yᵢᵀyᵢ
                c[f - 1] += np.einsum("ni,ni->i", Y, Y)
                n[f - 1] += len(Y)
    return NormalEquations(A, b, c, n, BlockEquations(G, h, block) if B else None)


def information_criteria(rss: FloatArray, n: float, n_eff: float, k: int
                         ) -> tuple[float, float]:
    """(BIC, AIC) of a fit with ``k`` parameters from its residual sums of squares.

    Parameters
    ----------
    rss : ndarray, shape (6,)
        RSS per DOF.
    n : float
        Samples the RSS sums over.
    n_eff : float
        Independent samples among them (the low-pass makes neighbours dependent).
    k : int
        Parameters fitted.
    """
    # n_eff Σ_i log(RSS_i / n): −2 log-likelihood up to a constant
    ll = n_eff * float(np.sum(np.log(np.maximum(rss, 1e-300) / n)))
    # BIC = … + k log n_eff, AIC = … + 2k
    return ll + k * float(np.log(n_eff)), ll + 2.0 * k


def total_sum_of_squares(ne: NormalEquations) -> FloatArray:
    """Σ (y − ȳ)² per DOF from the normal equations' Σ y² and the mean of y, shape (6,).

    The mean is the coefficient of a constant column, which the statistics do not hold, so
    Σ y² is returned: the NSE is then 1 − RSS/Σy², conservative for signals with an offset.
    """
    return np.asarray(ne.c.sum(0))
