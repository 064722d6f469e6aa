"""Candidate effects of the vehicle, its thrusters and its sensors: an :class:`Effect` has a
few unknown magnitudes p and predicts the residual ρ(p) it leaves in data analysed with the
believed model (ocean current, buoyancy and CG offset, thrust gain, delay, dead-zone, gyro and
DVL bias)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.gap.data import Chunk, GapData
from dampest_ros.core.physics.frames import matrix_from_euler
from dampest_ros.core.physics.rigid_body import coriolis_force, rigid_body_mass
from dampest_ros.core.signals.preprocess import zero_phase

FloatArray = NDArray[np.float64]

# --- effects --------------------------------------------------------------------------------


class Effect:
    """A candidate physical effect: unknown magnitudes p and the residual ρ(p) it leaves.

    Subclasses set the class attributes and implement :meth:`predict`; linear effects
    (ρ = X p) implement :meth:`columns` and set ``linear``; effects whose ρ does not depend
    on the velocity set ``applied_force``.

    Attributes
    ----------
    key : str
        Stable identifier, e.g. ``current``, ``linear.X_u``.
    family : str
        Group of alternatives, e.g. ``added_mass`` for the scale and the per-DOF versions.
    title : str
        The physical name shown to the user.
    params : tuple of str
        Names of the unknowns.
    units : tuple of str
    steps : tuple of float
        Typical resolution of each unknown: finite-difference step and solver scale.
    dofs : tuple of int
        Degrees of freedom the effect acts on directly.
    """

    key = ""
    family = ""
    title = ""
    params: tuple[str, ...] = ()
    units: tuple[str, ...] = ()
    steps: tuple[float, ...] = ()
    dofs: tuple[int, ...] = (0, 1, 2, 3, 4, 5)
    linear = False
    #: ρ does not depend on the velocity: the effect is a change of the applied force τ − ρ
    #: (or of g), which a free run can replay
    applied_force = False
    #: Indices of the unknowns that are magnitudes (0: the effect is absent), tested for
    #: significance; a shape parameter (a memory rate) is not among them. None: all.
    magnitudes: tuple[int, ...] | None = None

    @property
    def k(self) -> int:
        """Number of unknowns."""
        return len(self.params)

    def available(self, data: GapData) -> str:
        """Empty when the effect can be tested on ``data``, else the reason it cannot."""
        return ""

    def starts(self, data: GapData) -> list[FloatArray]:
        """Starting points of the screening (a grid over a shape parameter)."""
        return [np.zeros(self.k)]

    def implausible(self, data: GapData, p: FloatArray) -> str:
        """Why magnitudes p do not describe this effect on these data (empty: they do)."""
        return ""

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """Lower and upper bounds of p."""
        return np.full(self.k, -np.inf), np.full(self.k, np.inf)

    def predict(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        """ρ(p) on the rows of ``ch`` (unfiltered), shape (n, 6)."""
        if self.linear:
            return np.asarray(self.columns(data, ch, p) @ p, dtype=float)
        raise NotImplementedError

    def columns(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        """∂ρ/∂p at p, shape (n, 6, k): central differences unless overridden."""
        out = np.empty((len(ch), 6, self.k))
        lo, hi = self.bounds()
        for j in range(self.k):
            h = self.steps[j]
            a, b = p.copy(), p.copy()
            a[j], b[j] = max(p[j] - h, lo[j]), min(p[j] + h, hi[j])
            out[:, :, j] = (self.predict(data, ch, b) - self.predict(data, ch, a)) / (b[j] - a[j])
        return out

    def relative_velocity(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray | None:
        """The velocity the vehicle's damping sees on the rows of ``ch`` with magnitudes p,
        shape (n, 6) (m/s, rad/s), when the effect moves it away from the measured ν (a
        current: ν_r); None when it does not."""
        return None

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        """Magnitude ± σ in physical words."""
        s = np.sqrt(np.abs(np.diag(cov)))
        return ", ".join(f"{n} = {v:.4g} ± {e:.2g} {u}".rstrip()
                         for n, v, e, u in zip(self.params, p, s, self.units, strict=True))

    def magnitude(self, p: FloatArray) -> dict[str, float]:
        """Named magnitudes (for tests, tables and the model file)."""
        return {n: float(v) for n, v in zip(self.params, p, strict=True)}

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        """How the effect enters the model: ``{'theta': {name: Δ}}``, ``{'cross': [...]}``,
        ``{'freq': [...]}``, ``{'M': ΔM (6×6)}``, ``{'terms': {switch: bool}}`` (added-mass
        switches) and/or ``{'extra': {...}}``."""
        return {"extra": self.magnitude(p)}



class LinearEffect(Effect):
    """ρ = X(ν, ν̇, τ, η) p, exactly linear."""

    linear = True

    def columns(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        """X on the rows of ``ch``, shape (n, 6, k)."""
        raise NotImplementedError


class Current(Effect):
    """Ocean current constant in NED: the damping acts on ν_r = ν − [Rᵀ v_c; 0].

    With M_A ν̇_r in the true equation and ν̇_c = −ω × Rᵀ v_c for a constant NED current,

        ρ = C_A(ν_r)ν_r − C_A(ν)ν + D(ν_r)ν_r − D(ν)ν − M_A ν̇_c,

    the added-mass terms acting as the vehicle's switches say (no M_A ν̇_c without the
    inertial term, no C_A without the Coriolis term, C_A without Munk moments without them).

    Horizontal by default (north, east; m/s); ``vertical`` adds the down component.
    Memory states (if the model has them) are left out of the difference.
    """

    key = "current"
    family = "current"
    title = "ocean current (constant in NED, damping on the relative velocity)"
    dofs = (0, 1, 2, 5)

    def __init__(self, vertical: bool = False) -> None:
        self.params = ("v_north", "v_east", "v_down")[:3 if vertical else 2]
        self.units = ("m/s",) * self.k
        self.steps = (0.02,) * self.k

    def ned(self, p: FloatArray) -> FloatArray:
        """The current in NED (north, east, down; m/s), shape (3,)."""
        vc = np.zeros(3)
        vc[:self.k] = p
        return vc

    def relative_velocity(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        """ν_r = ν − [Rᵀ v_c; 0], shape (n, 6)."""
        return relative_motion(ch.nu, ch.R, self.ned(p))[0]

    def predict(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        nu_r, nu_c_dot = relative_motion(ch.nu, ch.R, self.ned(p))
        b = data.body
        out = (b.added_coriolis_force(nu_r) - b.added_coriolis_force(ch.nu)
               + data.damping_force(nu_r) - data.damping_force(ch.nu))
        if b.added_mass_terms.inertial:
            out -= nu_c_dot @ data.M_A.T
        return np.asarray(out, dtype=float)

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        m = self.magnitude(p)
        speed, heading = m["speed"], m["direction_deg"]
        # σ of speed and direction by linear propagation from the north/east covariance
        n, e = float(p[0]), float(p[1])
        C = cov[:2, :2]
        g_s = np.array([n, e]) / max(speed, 1e-12)
        g_d = np.degrees(np.array([-e, n]) / max(speed**2, 1e-24))
        s_s = float(np.sqrt(max(float(g_s @ C @ g_s), 0.0)))
        s_d = float(np.sqrt(max(float(g_d @ C @ g_d), 0.0)))
        text = (f"{speed:.3f} ± {s_s:.2g} m/s towards {heading:.1f}° ± {s_d:.2g}° "
                f"(north {n:+.3f}, east {e:+.3f} m/s)")
        if self.k == 3:
            text += f", down {float(p[2]):+.3f} m/s"
        return text

    def magnitude(self, p: FloatArray) -> dict[str, float]:
        out = super().magnitude(p)
        out["speed"] = float(np.hypot(p[0], p[1]))
        out["direction_deg"] = float(np.degrees(np.arctan2(p[1], p[0])) % 360.0)
        return out

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        return {"extra": {"current_ned": [float(x) for x in self.ned(p)]}}


def relative_motion(nu: FloatArray, R: FloatArray, v_c: FloatArray
                    ) -> tuple[FloatArray, FloatArray]:
    """The velocity relative to a current constant in NED and the current's rate in the body.

    Parameters
    ----------
    nu : ndarray, shape (n, 6)
        Body velocity ν (m/s, rad/s), FRD.
    R : ndarray, shape (n, 3, 3)
        Body → NED rotations.
    v_c : ndarray, shape (3,)
        The current (north, east, down; m/s).

    Returns
    -------
    nu_r : ndarray, shape (n, 6)
        ν − [Rᵀ v_c; 0].
    nu_c_dot : ndarray, shape (n, 6)
        ν̇_c = [−ω × Rᵀ v_c; 0] (m/s²).
    """
    vcb = np.einsum("nji,j->ni", R, v_c)  # Rᵀ v_c
    zero = np.zeros_like(vcb)
    nu_r = nu - np.concatenate([vcb, zero], axis=1)
    return nu_r, np.concatenate([-np.cross(nu[:, 3:], vcb), zero], axis=1)


class Buoyancy(LinearEffect):
    """Buoyancy minus weight differs by ΔB (N, positive: lighter in water than believed).

    The extra buoyancy acts upwards at the centre of buoyancy r_b:
    ρ = ΔB [Rᵀe_z; r_b × Rᵀe_z].
    """

    applied_force = True
    key = "buoyancy"
    family = "buoyancy"
    title = "buoyancy/weight offset (net buoyancy differs)"
    params = ("delta_B",)
    units = ("N",)
    steps = (0.5,)
    dofs = (2,)

    def columns(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        d = ch.down
        return np.concatenate([d, np.cross(data.body.r_b, d)], axis=1)[:, :, None]

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        s = float(np.sqrt(abs(cov[0, 0])))
        word = "lighter" if p[0] > 0 else "heavier"
        grams = abs(float(p[0])) / 9.81 * 1000
        return f"ΔB = {float(p[0]):+.3g} ± {s:.2g} N ({word} in water by {grams:.0f} g)"

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        return {"extra": {"buoyancy_offset": float(p[0])}}



class CGOffset(Effect):
    """Centre of gravity offset δ (m, FRD) from the believed r_g.

    Changes the restoring moment −δ × W Rᵀe_z and, through M_RB, the rigid-body inertia and
    Coriolis forces: ρ = ΔM_RB ν̇ + ΔC_RB(ν)ν + Δg(η). (A centre-of-buoyancy offset of
    −(W/B) δ gives the same restoring moment without the inertia change.)
    """

    key = "cg_offset"
    family = "cg_offset"
    title = "centre of gravity offset (restoring moment)"
    params = ("dx", "dy", "dz")
    units = ("m", "m", "m")
    steps = (0.002, 0.002, 0.002)
    dofs = (3, 4)

    def predict(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        b = data.body
        M1 = rigid_body_mass(b.mass, b.inertia, b.r_g + p)
        dM = M1 - data.M_RB
        d = ch.down
        out = ch.nu_dot @ dM.T + coriolis_force(M1, ch.nu) - coriolis_force(data.M_RB, ch.nu)
        # Δg(η) = −[0; δ × f_g] with f_g = W Rᵀe_z
        out[:, 3:] -= np.cross(p, b.weight * d)
        return np.asarray(out, dtype=float)

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        s = np.sqrt(np.abs(np.diag(cov)))
        return "δ = [" + ", ".join(f"{1e3 * v:+.2f} ± {1e3 * e:.2g}" for v, e in
                                   zip(p, s, strict=True)) + "] mm (FRD)"

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        return {"extra": {"cg_offset": [float(x) for x in p]}}


class ThrustGain(LinearEffect):
    """Actual thrust = (1 + ε) × logged thrust: ρ = −ε τ."""

    applied_force = True
    key = "thrust_gain"
    family = "thrusters"
    title = "thrust-gain error (actual thrust = (1 + ε) × logged)"
    params = ("epsilon",)
    units = ("",)
    steps = (0.01,)

    def columns(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        return -ch.tau[:, :, None]

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        return (f"ε = {100 * float(p[0]):+.2f} ± {100 * float(np.sqrt(abs(cov[0, 0]))):.2g} % "
                "of the logged thrust")

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        return {"extra": {"thrust_gain_error": float(p[0])}}



class Delay(Effect):
    """The vehicle feels the logged thrust d seconds late: ρ = τ(t) − τ(t − d)."""

    applied_force = True
    key = "delay"
    family = "thrusters"
    title = "time delay τ → ν (thrust acts later than logged)"
    params = ("delay",)
    units = ("s",)
    steps = (0.01,)
    grid = (0.03, 0.08, 0.14, 0.22, 0.32, 0.45)

    def starts(self, data: GapData) -> list[FloatArray]:
        return [np.array([d]) for d in self.grid]

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        return np.zeros(1), np.ones(1)

    def predict(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        # τ(t − d) by a band-limited (Fourier) fractional shift of the mirrored chunk, so
        # that ρ is smooth in d (linear interpolation has a kink at every sample period)
        n = len(ch)

        def spectrum() -> tuple[FloatArray, NDArray[np.complex128]]:
            ext = np.concatenate([ch.tau, ch.tau[::-1]], axis=0)
            return (np.asarray(np.fft.rfftfreq(2 * n, d=1.0 / data.rate), dtype=float),
                    np.fft.rfft(ext, axis=0))

        f, spec = data.memo(("tau_spectrum", ch.rows.start, ch.rows.stop), spectrum)
        shift = np.exp(-2j * np.pi * f * float(p[0]))[:, None]
        delayed = np.fft.irfft(spec * shift, n=2 * n, axis=0)[:n]
        return np.asarray(ch.tau - delayed, dtype=float)

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        return (f"d = {1e3 * float(p[0]):.1f} ± {1e3 * float(np.sqrt(abs(cov[0, 0]))):.2g} ms")

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        return {"extra": {"delay": float(p[0])}}



class DeadZone(Effect):
    """Rotors slower than n_dz (rev/s) give no thrust; the logged thrust does not know it.

    ρ = T_alloc f_lost, f_lost,j = logged thrust of thruster j while |n_j| < n_dz, resampled
    onto the samples the way the preprocessing resamples thrust (window centres, linear).
    Needs the logged rotor speeds (``thrusters/state`` of a bag).
    """

    applied_force = True
    key = "deadzone"
    family = "thrusters"
    title = "thruster dead-zone (no thrust at low rotor speed)"
    params = ("n_deadzone",)
    units = ("rev/s",)
    steps = (0.4,)
    grid = (1.5, 3.0, 4.5, 6.0, 8.0, 10.0, 13.0)

    def available(self, data: GapData) -> str:
        if data.joints is None or data.thrusters is None or len(data.joints) < 2:
            return "needs the logged rotor speeds (thrusters/state); CSV input has none"
        if not set(data.thrusters.names) <= set(data.joints.names):
            return "the logged thruster names do not match the vehicle's"
        return ""

    def starts(self, data: GapData) -> list[FloatArray]:
        return [np.array([g]) for g in self.grid]

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        return np.zeros(1), np.full(1, 30.0)

    def lost(self, data: GapData, n_dz: float) -> FloatArray:
        """τ lost in the dead-zone on every sample, shape (N, 6) (cached per n_dz)."""
        def table() -> FloatArray:
            j, th = data.joints, data.thrusters
            assert j is not None and th is not None
            order = [j.names.index(n) for n in th.names]
            n = j.velocity[:, order] / (2 * np.pi)
            f = np.where(np.abs(n) < n_dz, j.effort[:, order], 0.0)
            tau = f @ th.allocation.T
            window = float(np.median(np.diff(j.stamp)))
            tc = j.stamp - window / 2  # a message reports the mean over the window before it
            t = data.samples.t
            return np.stack([np.interp(t, tc, tau[:, i]) for i in range(6)], axis=1)

        out: FloatArray = data.memo(("deadzone", round(float(n_dz), 6)), table)
        return out

    def predict(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        return self.lost(data, max(float(p[0]), 0.0))[ch.rows]

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        s = float(np.sqrt(abs(cov[0, 0])))
        return (f"n_dz = {float(p[0]):.2f} ± {s:.2g} rev/s ({60 * float(p[0]):.0f} rpm); "
                "no thrust below it")

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        return {"extra": {"thruster_deadzone": float(p[0])}}



class GyroBias(Effect):
    """Constant gyro bias b (rad/s, FRD): the logs hold ω + b, and the body-frame
    acceleration the preprocessing forms (Rᵀ d/dt(Rv) − ω × v) holds −b × v.

    ρ = M [b × v; 0] + F(ν − [0; b]) − F(ν), F(ν) = C(ν)ν + D(ν)ν (M and C_A acting as
    the vehicle's added-mass switches say).
    """

    key = "gyro_bias"
    family = "sensor_bias"
    title = "gyro bias (measured angular rate offset)"
    params = ("bias_p", "bias_q", "bias_r")
    units = ("rad/s",) * 3
    steps = (0.005,) * 3
    dofs = (3, 4, 5)

    def predict(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        beta = np.concatenate([np.zeros(3), p])
        acc = np.zeros((len(ch), 6))
        acc[:, :3] = np.cross(p, ch.nu[:, :3])
        return np.asarray(acc @ data.body.M_inertial.T + data.static_force(ch.nu - beta)
                          - data.static_force(ch.nu), dtype=float)

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        s = np.sqrt(np.abs(np.diag(cov)))
        return "b_gyro = [" + ", ".join(f"{np.degrees(v):+.3f} ± {np.degrees(e):.2g}"
                                        for v, e in zip(p, s, strict=True)) + "] °/s (p, q, r)"

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        return {"extra": {"gyro_bias": [float(x) for x in p]}}

    def implausible(self, data: GapData, p: FloatArray) -> str:
        b, sd = attitude_gyro_bias(data)
        # a bias the attitude does not show: 5 σ of its block means, and 0.1 °/s
        off = np.abs(p - b) > 5.0 * sd + np.radians(0.1)
        if not off.any():
            return ""
        return ("the attitude measures the gyro bias as [" + ", ".join(
            f"{np.degrees(v):+.2f} ± {np.degrees(e):.2g}" for v, e in zip(b, sd, strict=True))
                + "] °/s (p, q, r): a modelling error, not a gyro bias")


def attitude_gyro_bias(data: GapData) -> tuple[FloatArray, FloatArray]:
    """The gyro bias the attitude shows: the mean of the logged body rates less the rates of
    the logged attitude (rad/s, FRD), with its standard deviation over the data's blocks
    (:attr:`GapData.block_index`), each shape (3,).

    Between consecutive samples of a segment R_kᵀ R_{k+1} = exp(S(ω Δt)): the attitude's rate
    is ω = vee(R_kᵀ R_{k+1} − R_{k+1}ᵀ R_k) / (2 Δt) (small angles), against the mean of the
    two logged rates. The attitude comes from the orientation, not from the gyro, so a real
    bias shows here and a modelling error does not.
    """
    def make() -> tuple[FloatArray, FloatArray]:
        s = data.samples
        R = matrix_from_euler(s.euler)
        same = s.segment[1:] == s.segment[:-1]
        D = np.einsum("nji,njk->nik", R[:-1], R[1:])[same]  # R_kᵀ R_{k+1}
        dt = np.diff(s.t)[same]
        # vee of the skew part / Δt
        w_att = np.stack([D[:, 2, 1] - D[:, 1, 2], D[:, 0, 2] - D[:, 2, 0],
                          D[:, 1, 0] - D[:, 0, 1]], axis=1) / (2.0 * dt[:, None])
        w_log = 0.5 * (s.nu[:-1, 3:] + s.nu[1:, 3:])[same]
        diff = w_log - w_att
        _, idx = np.unique(data.block_index[:-1][same], return_inverse=True)
        count = np.bincount(idx)
        means = np.stack([np.bincount(idx, diff[:, i]) / count for i in range(3)], axis=1)
        sd = means.std(axis=0, ddof=1) / np.sqrt(len(means)) if len(means) > 1 else \
            np.full(3, np.inf)
        return diff.mean(axis=0), sd
    result: tuple[FloatArray, FloatArray] = data.memo(("attitude_gyro_bias",), make)
    return result


class DvlBias(Effect):
    """Constant DVL velocity bias b (m/s, FRD) seen through the DVL/IMU fusion.

    The preprocessing fuses R v_dvl below the crossover f_c with the integrated IMU above it
    (:func:`dampest_ros.core.signals.preprocess.fuse_velocity`), so the logged velocity and its
    derivative carry β = Rᵀ LP_c(R b) and β̇ = Rᵀ d/dt LP_c(R b) − ω × β (both → b and 0
    when the attitude changes slowly):

        ρ = −M [β̇; 0] + F(ν − [β; 0]) − F(ν),   F(ν) = C(ν)ν + D(ν)ν

    (M and C_A acting as the vehicle's added-mass switches say).
    """

    key = "dvl_bias"
    family = "sensor_bias"
    title = "DVL bias (measured velocity offset, fixed in the body)"
    params = ("bias_u", "bias_v", "bias_w")
    units = ("m/s",) * 3
    steps = (0.01,) * 3
    dofs = (0, 1, 2)

    def predict(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        b_ned = np.einsum("nij,j->ni", ch.R, p)
        lp = zero_phase(b_ned, data.rate, data.crossover)
        lp_dot = zero_phase(b_ned, data.rate, data.crossover, derivative=True)
        beta = np.einsum("nji,nj->ni", ch.R, lp)
        beta_dot = np.einsum("nji,nj->ni", ch.R, lp_dot) - np.cross(ch.nu[:, 3:], beta)
        acc = np.concatenate([beta_dot, np.zeros_like(beta)], axis=1)
        shift = np.concatenate([beta, np.zeros_like(beta)], axis=1)
        return np.asarray(-acc @ data.body.M_inertial.T + data.static_force(ch.nu - shift)
                          - data.static_force(ch.nu), dtype=float)

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        s = np.sqrt(np.abs(np.diag(cov)))
        return "b_dvl = [" + ", ".join(f"{v:+.4f} ± {e:.2g}" for v, e in
                                       zip(p, s, strict=True)) + "] m/s (u, v, w)"

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        return {"extra": {"dvl_bias": [float(x) for x in p]}}
