"""Where the residual is: per DOF, velocity regime, frequency band (Welch PSD), time segment,
attitude and depth (:func:`localise`)."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from dampest_ros.core.gap.data import rms
from dampest_ros.core.physics.rigid_body import DOF_NAMES
from dampest_ros.core.signals.samples import Samples

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

# --- localisation -----------------------------------------------------------------------------


@dataclass
class LocalRow:
    """Residual RMS per DOF in one subset of the data.

    Attributes
    ----------
    group : str
        ``all``, ``speed``, ``sign``, ``band``, ``time``, ``attitude`` or ``depth``.
    label : str
        The subset, e.g. ``|u| high``, ``0.05–0.2 Hz``, ``t 100–200 s``.
    share : float
        Share of the samples (or of the bandwidth) in the subset.
    rms : ndarray, shape (6,)
        Residual RMS per DOF in the subset (N, N·m).
    """

    group: str
    label: str
    share: float
    rms: FloatArray


BANDS = (0.0, 0.05, 0.2, 0.5, 1.0, 2.0)


def localise(samples: Samples, r: FloatArray, n_time: int = 6,
             bands: Sequence[float] = BANDS, passband: float = 0.0) -> list[LocalRow]:
    """Where the residual is: RMS per DOF by velocity regime, band, time, attitude, depth.

    Parameters
    ----------
    samples : Samples
    r : ndarray, shape (N, 6)
        Residual (N, N·m).
    n_time : int
        Number of equal time segments.
    bands : sequence of float
        Band edges (Hz) of the residual spectrum (Welch PSD per segment, averaged).
    passband : float
        Highest frequency the residual holds (the regression's low-pass, Hz); bands stop
        there and their ``share`` is their share of [0, passband]. 0: the Nyquist frequency.

    Returns
    -------
    list of LocalRow
        The first row is ``all``; in band rows ``rms`` is the band's RMS (√∫PSD df).
    """
    rows = [LocalRow("all", "all data", 1.0, rms(r, np.ones(len(r), dtype=bool)))]
    nu = samples.nu
    for i, n in enumerate(DOF_NAMES):
        a = np.abs(nu[:, i])
        med = float(np.median(a))
        for label, m in ((f"|{n}| low (< {med:.2g})", a < med),
                         (f"|{n}| high (≥ {med:.2g})", a >= med)):
            if m.any():
                rows.append(LocalRow("speed", label, float(m.mean()), rms(r, m)))
        for label, m in ((f"{n} > 0", nu[:, i] > 0), (f"{n} < 0", nu[:, i] < 0)):
            if m.any():
                rows.append(LocalRow("sign", label, float(m.mean()), rms(r, m)))
    rate = samples.rate
    top = passband if 0 < passband < rate / 2 else rate / 2
    f, P = residual_psd(samples, r)
    edges = [b for b in bands if b < top] + [top]
    for lo, hi in itertools.pairwise(edges):
        m = (f >= lo) & (f < hi)
        df = float(f[1] - f[0]) if len(f) > 1 else 1.0
        rows.append(LocalRow("band", f"{lo:g}–{hi:g} Hz", (hi - lo) / top,
                             np.sqrt(np.sum(P[m], axis=0) * df)))
    t = samples.t
    cuts = np.linspace(t[0], t[-1] + 1e-9, n_time + 1)
    for a, b in itertools.pairwise(cuts):
        m = (t >= a) & (t < b)
        if m.any():
            rows.append(LocalRow("time", f"t {a - t[0]:.0f}–{b - t[0]:.0f} s", float(m.mean()),
                                 rms(r, m)))
    for j, name in ((0, "roll"), (1, "pitch")):
        a = np.degrees(np.abs(samples.euler[:, j]))
        med = float(np.median(a))
        for label, m in ((f"|{name}| < {med:.0f}°", a < med), (f"|{name}| ≥ {med:.0f}°",
                                                                a >= med)):
            if m.any():
                rows.append(LocalRow("attitude", label, float(m.mean()), rms(r, m)))
    d = samples.depth
    if np.isfinite(d).any():
        med = float(np.nanmedian(d))
        for label, m in ((f"depth < {med:.1f} m", d < med), (f"depth ≥ {med:.1f} m", d >= med)):
            if m.any():
                rows.append(LocalRow("depth", label, float(m.mean()), rms(r, m)))
    return rows


def residual_psd(samples: Samples, r: FloatArray, mask: BoolArray | None = None,
                 window: float = 40.0) -> tuple[FloatArray, FloatArray]:
    """One-sided Welch PSD of r, averaged over segments (weighted by their length).

    Parameters
    ----------
    samples : Samples
    r : ndarray, shape (N, 6)
    mask : ndarray of bool, shape (N,), optional
        Rows to use (each contiguous run within a segment is one record).
    window : float
        Welch segment length (s).

    The mean is kept (no detrending): a constant offset (e.g. a buoyancy error) is part of
    the residual and belongs to the lowest band.

    Returns
    -------
    f : ndarray, shape (F,)
        Hz.
    P : ndarray, shape (F, 6)
        (N² or (N·m)²) per Hz.
    """
    rate = samples.rate
    keep = np.ones(len(r), dtype=bool) if mask is None else mask
    nper = max(16, min(round(window * rate), int(keep.sum())))
    f = np.fft.rfftfreq(nper, 1.0 / rate)
    P = np.zeros((len(f), 6))
    total = 0
    for sl in samples.segments():
        rows = np.flatnonzero(keep[sl]) + (sl.start or 0)
        n = len(rows)
        if n < nper or np.any(np.diff(rows) != 1):
            continue
        _, p = signal.welch(r[rows], fs=rate, nperseg=nper, axis=0, detrend=False)
        P += p * n
        total += n
    if total == 0:
        x = r[keep]
        _, p = signal.welch(x, fs=rate, nperseg=min(nper, len(x)), axis=0, detrend=False)
        f = np.fft.rfftfreq(min(nper, len(x)), 1.0 / rate)
        return np.asarray(f, dtype=float), np.asarray(p, dtype=float)
    return np.asarray(f, dtype=float), np.asarray(P / total, dtype=float)


def concentration(rows: Sequence[LocalRow], top: int = 3) -> list[tuple[int, str, float]]:
    """Per DOF, the subsets where the residual RMS is most above its overall RMS.

    Band rows are compared by RMS per unit bandwidth against the whole spectrum's.

    Returns
    -------
    list of (dof, label, ratio)
        ``top`` entries per DOF, largest ratio first.
    """
    total = rows[0].rms
    out = []
    for i in range(6):
        scored = []
        for row in rows[1:]:
            if row.group == "band":
                ratio = float(row.rms[i] / max(total[i], 1e-300) / np.sqrt(max(row.share,
                                                                                1e-12)))
            else:
                ratio = float(row.rms[i] / max(total[i], 1e-300))
            scored.append((ratio, row.label))
        scored.sort(reverse=True)
        out += [(i, label, ratio) for ratio, label in scored[:top]]
    return out
