"""Fossen's equation of motion and the vehicle it describes.

M ν̇ + C(ν)ν + D(ν)ν + g(η) = τ: the rigid body and its added mass (:mod:`.rigid_body`), the
damping D(ν) as named terms with basis matrices and scalar functions α_k(ν) (:mod:`.damping`,
:mod:`.terms`, :mod:`.alpha`; the drag of elements at points of the body, :mod:`.point_drag`),
the thrusters and their allocation (:mod:`.thrusters`), the hull
geometry behind the presets (:mod:`.geometry`), where the sensors sit (:mod:`.mounting`), the
one conversion between ROS's FLU/ENU and Fossen's FRD/NED (:mod:`.frames`) and the vehicle that
joins them (:mod:`.vehicle`).

May import: numpy and scipy only; nothing else of dampest_ros. Every other room of
:mod:`dampest_ros.core` builds on this one.
"""
