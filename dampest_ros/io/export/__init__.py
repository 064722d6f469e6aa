"""Export a model to simulator and controller formats, and import it back.

One module per target (docs/architecture.md §5), each with the conventions read from the
target project's source: :mod:`.gz` (gz-sim Hydrodynamics plugin), :mod:`.urdf` (the
``<hydrodynamics>`` block of the RDML hydrodynamics library), :mod:`.uuv` (UUV Simulator's
HMFossen model in its underwater-object plugin, SDF); :mod:`.common` holds what they share (the
model as single coefficients, the added mass, the header, the refusals) and :mod:`.convert`
the dispatch by format (:func:`~.convert.export_model`, :func:`~.convert.import_model`).

dampest stores D(ν)ν on the left-hand side with dissipative coefficients positive, in FRD.
Added mass is the model file's ``model.M_A`` when it has one, else M_A = M − M_RB with the
vehicle's rigid body; with neither only the damping is exported (and the output says so).
The added-mass switches (``model.added_mass_terms``, else the vehicle's) become gz-sim's
``<disable_added_mass>`` (``inertial: false``) and ``<disable_coriolis>`` (``coriolis:
false``); gz-sim has no switch for the Munk moments alone (its C_A(ν)ν always holds them), and
the URDF block and UUV Simulator have no switches at all: such a combination is listed as
left out, as are off-diagonal M_A entries in gz-sim's C_A(ν)ν (built from the diagonal of M_A
only; they act in its M_A ν̇). Terms a format cannot express (fluid memory, residual modes,
|U| or product α) are listed in the output and raised as :class:`~.common.ExportWarning`; nothing is
dropped silently.

Two things are never exported silently. Each written coefficient is labelled in the file's
header ``estimate``, ``constrained (was …)`` (by the fit's dissipativity constraint or by
``clamp``) or ``held at prior`` (not determined by the data; also an
:class:`~.common.ExportWarning`). And simulators apply the linear and |ν|ν terms at every
speed, not only where the vehicle flew: the coefficients a format writes are checked in that
format's form at every speed (:func:`~.common.turns`: per DOF linear ≥ 0 and quadratic
≥ 0, couplings on ν directions); a set that turns non-dissipative is refused with
:class:`~.common.NotDissipativeError` naming the coefficient and the speed, unless ``clamp``
(the nearest dissipative set, labelled) or ``force`` (as is, labelled NOT DISSIPATIVE).

This module itself only names the formats (no imports), so that ``dampest export --help``
does not load numpy.
"""

#: Export targets.
FORMATS = ("gz", "urdf", "uuv")
#: Formats :func:`~.convert.import_model` reads.
IMPORT_FORMATS = ("gz", "urdf", "uuv")
#: Body frames of a gz link: ``flu`` (REP-103, Gazebo's default) or ``frd``.
FRAMES = ("flu", "frd")
