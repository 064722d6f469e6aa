"""The simulator's ground-truth record, in Fossen's frames (FRD body, NED world)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass
class Trajectory:
    """Ground truth at the integration step, stacked over N steps.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Time (s), uniform with step ``dt``.
    position : ndarray, shape (N, 3)
        Body origin in NED (m); z is depth.
    quaternion : ndarray, shape (N, 4)
        Attitude, body FRD → NED, scalar first [w, x, y, z].
    nu : ndarray, shape (N, 6)
        Body velocity over ground [u, v, w, p, q, r] (m/s, rad/s).
    nu_dot : ndarray, shape (N, 6)
        Its time derivative (m/s², rad/s²).
    tau : ndarray, shape (N, 6)
        Generalised force the thrusters actually applied, mean over [t, t + dt] (N, N·m).
    rotor_speed : ndarray, shape (N, n_thrusters)
        Rotor speed a real vehicle would log, mean over [t, t + dt] (rev/s).
    thrust : ndarray, shape (N, n_thrusters)
        Thrust a real vehicle would log (the nominal curve of the logged rotor speed), mean
        over [t, t + dt] (N). Thruster telemetry is a window average, like an ESC's rpm
        counter; the step means let the sensor model average over any window.
    current : ndarray, shape (N, 3)
        Water current in NED (m/s).
    memory : ndarray, shape (N, n_states)
        Fluid-memory filter states of the true model.
    thruster_names : tuple of str
    hydro : ndarray, shape (N, 6), optional
        The plant's own hydrodynamic wrench on the vehicle (FRD, about the origin, N and
        N·m, acting on it: right-hand side), where the plant reports one (MuJoCo's
        ``qfrc_fluid``); for evaluation only.
    """

    t: FloatArray
    position: FloatArray
    quaternion: FloatArray
    nu: FloatArray
    nu_dot: FloatArray
    tau: FloatArray
    rotor_speed: FloatArray
    thrust: FloatArray
    current: FloatArray
    memory: FloatArray
    thruster_names: tuple[str, ...] = ()
    hydro: FloatArray | None = None

    @property
    def dt(self) -> float:
        """Integration step (s)."""
        return float(self.t[1] - self.t[0]) if len(self.t) > 1 else 0.0

    def __len__(self) -> int:
        return int(self.t.shape[0])
