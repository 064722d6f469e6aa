"""The simulators and what they fly: truth, sensors and excitation.

The native simulator (:mod:`.simulate`) and the MuJoCo backend whose fluid model we did not
write (:mod:`.mujoco_backend`), the hidden physical effects they can apply (:mod:`.effects`),
the sensor models (:mod:`.sensors`) and the live tick-by-tick stream (:mod:`.stream`); the
trajectory between integration steps (:mod:`.trajectory`, :mod:`.interpolate`), the velocity
controller (:mod:`.control`), the excitation protocols (:mod:`.excitation`) and the
finite-Fourier-series design engine shared with the arm (:mod:`.design`,
:mod:`.vehicle_design`).

May import: :mod:`dampest_ros.core.signals` and :mod:`dampest_ros.core.physics`; never
:mod:`dampest_ros.core.identification` (the simulators do not know how they are identified).
"""
