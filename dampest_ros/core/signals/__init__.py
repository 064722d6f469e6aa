"""From sensor messages to samples: the time series identification consumes.

The containers of sensor series in ROS frames (:mod:`.measurements`), the synchronised samples
of ν, ν̇, τ and attitude in Fossen's frames (:mod:`.samples`), the offline preprocessing that
turns one into the other (:mod:`.preprocess`: sync, Kalman filtering, mounting, thrust
allocation; :mod:`.sources`: navigation-state topics as velocity and attitude, and the
signals they lack), the deterministic merge of message streams into stamp order
(:mod:`.reorder`), and the one rule for gaps and jittered stamps (:mod:`.resample`).

May import: :mod:`dampest_ros.core.physics`.
"""
