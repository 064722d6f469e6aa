"""arm_estimator_node: recursive least squares of an arm's base parameters and joint friction
on live sensor_msgs/JointState.

Subscribes joint_states (sensor-data QoS; position and effort of the arm's joints, in any
order: they are matched by name). The samples are filtered as offline (zero-phase low-pass at
cutoff, q̇ and q̈ of the filtered q, decimation to rate_out) in windows that reach 10 / cutoff s
past the samples they emit, so the estimate lags the data by that margin plus hop. The work is
done by dampest_ros.core.arm.online.ArmEstimator: the vehicle estimator's RLS (forgetting,
per-joint noise weights unless adapt_weights is false, CUSUM change alarm with a covariance
reset on an alarm) on the base regressor with friction columns, from the prior of
dampest_ros.core.arm.online.prior_std (or a model file).

Holds the estimate as the parameters model.kind (arm_base_parameters), model.arm,
model.joint_names, model.parameter_names (each base parameter named by the full parameter it
keeps), model.theta, model.theta_std, model.identified, model.mapping (what each base
parameter combines), model.coulomb_width (the dry-friction form of the Coulomb parameters)
and model.version (bumped at each publish), read-only from outside,
and publishes it on dampest/arm_model (std_msgs/String with the model file YAML, transient
local) and on /diagnostics (diagnostic_msgs/DiagnosticArray: per joint innovation RMS, noise
and excitation, covariance trace, lag, the change alarms with their time and joints, and every
counter: count.received, used, rejected_joints (messages without the arm's joints),
rejected_fields (position or effort missing), rejected_nonfinite, rejected_implausible (an
effort over 10 × the joint's effort limit, a position far outside its limits:
dampest_ros.core.arm.online.implausible), dropped_out_of_order, clock_jumps, gaps,
filter_errors, resume_refused: the node's life totals, kept when a parameter change rebuilds
the estimator or ~/reset restarts it) and what resume did. A change alarm is
published on /diagnostics at once. Services: ~/reset (std_srvs/Trigger, back to the prior),
~/save (Trigger, atomic write of the model file to save_path), ~/freeze (std_srvs/SetBool:
stop or resume updating). With resume (default) it starts from the model file at save_path
with its version when that file holds this arm's base parameters.

The arm is the parameter arm with the joints of lock held fixed at 0 (a gripper's: a Panda's
fingers), as dampest arm --lock. A prior or resumed model file identified with another
coulomb_width than the node's is refused in one line naming both widths (its Coulomb
parameters mean another friction form; adopting it quietly would change what the parameter
says): a prior at start ends the node with status 2, a resumed file is counted
(resume_refused), a change of either parameter while running is rejected. One identified
with other joints locked (``dampest arm identify --lock``) is refused the same way, naming
the file's lock and the node's.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from dampest_ros.core.arm.base import base_parameters
from dampest_ros.core.arm.identify import IdentifyConfig
from dampest_ros.core.arm.model import arm_model_identity
from dampest_ros.core.arm.online import ArmEstimate, ArmEstimator, default_rls, prior_std
from dampest_ros.core.arm.regressor import full_parameters
from dampest_ros.core.physics.identity import Identity, mismatch, unchecked
from dampest_ros.io.arm import (
    ArmDataError,
    arm_model_parameters,
    arm_model_text,
    joint_list,
    load_arm,
    load_arm_model,
    save_arm_model,
)
from dampest_ros.ros.common import (
    DIAGNOSTICS_TOPIC,
    LATCHED_QOS,
    RELIABLE_QOS,
    SENSOR_QOS,
    EstimatorParamNode,
    Param,
    arm_problem,
    diagnostic_array,
    main_for,
    save_path_check,
    stamp_ns,
)
from dampest_ros.ros.convert import joint_columns

#: Messages buffered before they are handed to the estimator (a quarter second at 1 kHz).
HANDOVER = 250


def _width(w: float) -> str:
    """A Coulomb width as the dry-friction form it means."""
    return f"{w:g} rad/s (Fc·tanh(q̇/{w:g}))" if w > 0 else "0 (Fc·sign(q̇))"


def _prior_check(value: Any) -> str | None:
    if not str(value).strip():
        return None
    try:
        load_arm_model(str(value))
    except ArmDataError as exc:
        return f"prior: {exc}"
    return None


class ArmEstimatorNode(EstimatorParamNode):
    """Arm estimator node (see the module docstring)."""

    NODE_NAME = "arm_estimator_node"
    PARAMS = (
        Param("arm", "ur5", "arm preset or URDF path (an MJCF beside it, or written from "
              "the URDF): joint names, "
              "kinematics and the nominal parameters (the prior mean)"),
        Param("lock", "", "joints held fixed at 0 (a gripper's, e.g. "
              "'panda_finger_joint1,panda_finger_joint2'), comma separated, as dampest arm "
              "--lock; for a URDF without an MJCF beside it ('': none)"),
        Param("cutoff", 10.0, "zero-phase low-pass of q and torque in Hz (at most "
              "rate_out/2)", low=0.5, high=200.0),
        Param("rate_out", 50.0, "rate the filtered samples are decimated to, one RLS update "
              "each, in Hz (at most the JointState rate)", low=1.0, high=1000.0),
        Param("min_speed", 0.1, "a joint's rows slower than this (rad/s) are not used: dry "
              "friction is undefined at rest", low=0.0, high=10.0),
        Param("coulomb_width", 0.0, "dry friction as Fc·tanh(q̇/width) with this width in "
              "rad/s (0: Fc·sign(q̇)); must be the one a prior or resumed model file was "
              "identified with (another is refused, naming both)", low=0.0, high=10.0),
        Param("forgetting_factor", 0.9995, "RLS forgetting factor λ (memory ≈ 1/(1−λ) "
              "samples at rate_out)", low=0.9, high=1.0),
        Param("hop", 1.0, "s of samples filtered per pass (the estimate lags by 10/cutoff + "
              "hop s)", low=0.05, high=10.0),
        Param("prior", "", "arm model YAML (this node's ~/save) whose theta/theta_std are the "
              "prior ('': the arm's nominal parameters, σ = prior_std_factor·|θ| + what "
              "moves a joint's torque by 10 % of its effort limit)", check=_prior_check),
        Param("prior_std_factor", 1.0, "prior σ of the nominal parameters relative to their "
              "magnitude (added to the torque-scaled part)", low=1e-6, high=1e6),
        Param("adapt_weights", True, "weight each joint's rows by its estimated noise "
              "variance (false: equal weights)"),
        Param("publish_rate", 1.0, "model and diagnostics publications per second (node "
              "clock)", low=0.01, high=100.0),
        Param("save_path", "dampest_arm_model.yaml", "where ~/save writes the model YAML",
              check=save_path_check),
        Param("resume", True, "at start, continue from the model file at save_path (its θ, "
              "σ and version) when it holds this arm's base parameters; false: start from "
              "the prior", read_only=True),
    )

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.NODE_NAME, self.PARAMS, **kwargs)
        self.version = 0
        self.counts = dict.fromkeys(
            ("received", "used", "rejected_joints", "rejected_fields", "rejected_nonfinite",
             "dropped_out_of_order", "clock_jumps", "filter_errors"), 0)
        self._build()
        if self.p("resume"):
            start = self.saved_model(load_arm_model, self._mismatch)
            if start is not None:
                self._build(start)
        self.serve_model(self._model_values())
        self.pub_model = self.create_publisher(String, "dampest/arm_model", LATCHED_QOS)
        self.pub_diag = self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, RELIABLE_QOS)
        self.create_subscription(JointState, "joint_states", self._on_joint_state, SENSOR_QOS)
        self.start_services()
        self._used_at_publish = -1
        self.last_error = ""

    def _build(self, start: ArmEstimate | None = None) -> None:
        """A new estimator (and an empty buffer) from ``start`` (a resumed model file) or
        else the prior."""
        if not 2.0 * self.p("cutoff") <= self.p("rate_out"):
            raise ValueError(f"parameter cutoff {self.p('cutoff')} Hz must be at most "
                             f"rate_out/2 = {0.5 * self.p('rate_out')} Hz")
        reason = arm_problem(self.p("arm"), self.p("lock"))
        if reason is not None:
            raise ValueError(f"parameter {reason}")
        self.arm = load_arm(self.p("arm"), lock=joint_list(self.p("lock")))
        base = base_parameters(self.arm.model)
        theta0 = base.of(full_parameters(self.arm.model, self.arm.dynamics))
        std0 = prior_std(self.arm.model, base, theta0, self.p("prior_std_factor"))
        self._kept = [base.names[i] for i in base.independent]
        if start is None and str(self.p("prior")).strip():
            start = load_arm_model(self.p("prior"))
            reason = self._mismatch(start)
            if reason is not None:
                raise ValueError(f"parameter prior: {self.p('prior')} {reason}")
        if start is not None:
            theta0, std0 = start.theta, np.maximum(start.theta_std, 1e-12)
        cfg = IdentifyConfig(cutoff=self.p("cutoff"), rate_out=self.p("rate_out"),
                             min_speed=self.p("min_speed"),
                             coulomb_width=self.p("coulomb_width"))
        rls = default_rls(self.arm.model, base, theta0, self.p("forgetting_factor"),
                          self.p("adapt_weights"))
        self.estimator = ArmEstimator(self.arm.model, base, theta0, std0, cfg, rls,
                                      hop=self.p("hop"), identity=self.owner())
        self.names = tuple(self.arm.model.names)
        self._order: dict[tuple[str, ...], np.ndarray | None] = {}
        self._t: list[float] = []
        self._q: list[np.ndarray] = []
        self._tau: list[np.ndarray] = []
        self._last = -np.inf
        self._alarms_reported = 0  # the alarms of this estimator published so far

    def owner(self) -> Identity:
        return arm_model_identity(str(self.p("arm")), self.arm.model, self._kept)

    def _mismatch(self, m: ArmEstimate) -> str | None:
        """Why arm model ``m`` does not hold this arm's base parameters (None: it does; a
        file without an identity is taken with a warning)."""
        source = str(self.p("save_path"))
        why = self._lock_mismatch(m) or mismatch(m.identity, self.owner(), source)
        if why is not None:
            return why
        warning = unchecked(m.identity, self.owner(), source)
        if warning is not None:
            self.get_logger().warning(warning)
        if m.coulomb_width != self.p("coulomb_width"):
            return self._width_mismatch(m.coulomb_width, self.p("coulomb_width"))
        if m.parameter_names != self._kept:
            return (f"holds the base parameters of another arm ({len(m.parameter_names)} "
                    f"named, {self.p('arm')} has {len(self._kept)}: {self._kept[:3]} ...)")
        return None

    def _lock_mismatch(self, m: ArmEstimate) -> str | None:
        """Why arm model ``m``, made with other joints of this arm locked, does not fit this
        node's ``lock`` (None: same joints, or joints of another arm)."""
        mine = tuple(self.arm.model.names)
        held = list(joint_list(self.p("lock")))
        if tuple(m.joint_names) == mine or not set(m.joint_names) <= {*mine, *held}:
            return None
        theirs = [j for j in (*mine, *held) if j not in m.joint_names]
        fix = f"--lock {','.join(held)}" if held else "without --lock"
        return (f"was identified with lock {','.join(theirs) or '(none)'}, this node's lock "
                f"is {','.join(held) or '(none)'}: its parameters belong to the joints "
                f"{', '.join(m.joint_names)}; set -p lock:={','.join(theirs)}, or identify "
                f"it again {fix}")

    @staticmethod
    def _width_mismatch(file_width: float, node_width: float) -> str:
        """Why a model file of another Coulomb width is refused, and how to fix it."""
        return (f"was identified with coulomb_width {_width(file_width)}, this node's "
                f"coulomb_width is {_width(node_width)}; its Coulomb parameters belong to "
                f"its form: set -p coulomb_width:={file_width:g}, or identify it again with "
                f"--coulomb-width {node_width:g}")

    def _model_values(self) -> dict[str, Any]:
        return arm_model_parameters(self.estimator.estimate(self.version), self.p("arm"))

    def check_parameter(self, name: str, value: Any) -> str | None:
        if name in ("arm", "lock"):
            return arm_problem(*((value, self.p("lock")) if name == "arm"
                                       else (self.p("arm"), value)))
        prior = str(value if name == "prior" else self.p("prior")).strip()
        if name in ("prior", "coulomb_width") and prior:
            width = float(value) if name == "coulomb_width" else self.p("coulomb_width")
            try:
                file_width = load_arm_model(prior).coulomb_width
            except (ArmDataError, OSError) as exc:
                return f"prior: {exc}"
            if file_width != width:
                return f"prior: {prior} {self._width_mismatch(file_width, width)}"
        if name == "cutoff" and not 2.0 * value <= self.p("rate_out"):
            return f"cutoff must be at most rate_out/2 = {0.5 * self.p('rate_out')} Hz, got " \
                   f"{value}"
        if name == "rate_out" and not value >= 2.0 * self.p("cutoff"):
            return f"rate_out must be at least 2 × cutoff = {2.0 * self.p('cutoff')} Hz, got " \
                   f"{value}"
        return None

    # --- input ---------------------------------------------------------------------------------

    def _columns(self, names: tuple[str, ...]) -> np.ndarray | None:
        """Where the arm's joints are in a message naming ``names`` (None: not all there;
        the first such message is logged)."""
        if names not in self._order:
            self._order[names], missing = joint_columns(self.names, names)
            if missing:
                self.get_logger().error(
                    f"joint_states names {list(names)} lack the joints {missing} of arm "
                    f"{self.p('arm')}; such messages are rejected (count.rejected_joints): "
                    "remap the arm's topic or set the parameter arm")
        return self._order[names]

    def _on_joint_state(self, m: JointState) -> None:
        c = self.counts
        c["received"] += 1
        cols = self._columns(tuple(m.name))
        if cols is None:
            c["rejected_joints"] += 1
            return
        if len(m.position) != len(m.name) or len(m.effort) != len(m.name):
            c["rejected_fields"] += 1
            return
        q = np.asarray(m.position, dtype=float)[cols]
        tau = np.asarray(m.effort, dtype=float)[cols]
        t = stamp_ns(m.header.stamp) * 1e-9
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(tau))):
            c["rejected_nonfinite"] += 1
            return
        if t <= self._last:
            if t < self._last - 1.0:  # the source restarted its clock: start the stream anew
                c["clock_jumps"] += 1
                self._hand_over()
                self.estimator.clear()
                self.get_logger().warning(f"joint_states clock jumped back by "
                                          f"{self._last - t:.3f} s; filtering restarted, "
                                          "estimate kept")
            else:
                c["dropped_out_of_order"] += 1
                return
        self._last = t
        self._t.append(t)
        self._q.append(q)
        self._tau.append(tau)
        if len(self._t) >= HANDOVER:
            self._hand_over()

    def _hand_over(self) -> None:
        """Give the buffered samples to the estimator; a change alarm is published at once."""
        if not self._t:
            return
        t, q, tau = np.array(self._t), np.array(self._q), np.array(self._tau)
        self._t, self._q, self._tau = [], [], []
        try:
            self.counts["used"] += self.estimator.add(t, q, tau)
        except ValueError as exc:  # rates that do not fit cutoff and rate_out
            self.counts["filter_errors"] += 1
            self.estimator.clear()
            if str(exc) != self.last_error:
                self.get_logger().error(f"joint_states cannot be filtered: {exc}")
            self.last_error = str(exc)
        if len(self.estimator.alarms) > self._alarms_reported:
            self._publish_diagnostics()

    # --- output --------------------------------------------------------------------------------

    def _publish(self, force: bool = False) -> None:
        self._hand_over()
        if force or self.counts["used"] != self._used_at_publish:
            self._used_at_publish = self.counts["used"]
            self.version += 1
            est = self.estimator.estimate(self.version)
            self.serve_model(arm_model_parameters(est, self.p("arm")))
            self.pub_model.publish(String(data=arm_model_text(est, self.p("arm"))))
        self._publish_diagnostics()

    def _publish_diagnostics(self) -> None:
        e = self.estimator
        d = e.rls.diagnostics(condition=False)
        values: dict[str, Any] = {f"count.{k}": v for k, v in self.counts.items()}
        values.update(self.life_counts(self._estimator_counts()))
        values["count.resume_refused"] = self.resume_refused
        values["resume"] = self.resumed
        values["model.version"] = self.version
        values["estimated_until_s"] = e.emitted if np.isfinite(e.emitted) else "none yet"
        values["lag_s"] = self._last - e.emitted if np.isfinite(e.emitted) else "none yet"
        for j, name in enumerate(self.names):
            values[f"{name}.innovation_rms"] = float(d.innovation_rms[j])
            values[f"{name}.noise_std"] = float(d.noise_std[j])
            values[f"{name}.excitation"] = float(d.excitation[j])
        values["covariance_trace"] = d.covariance_trace
        values["alarms"] = len(e.alarms)
        level, message = 0, "ok"
        if e.alarms:
            values["last_alarm_s"] = e.alarms[-1]
            values["last_alarm_joints"] = ", ".join(e.alarm_joints[-1])
        if len(e.alarms) > self._alarms_reported:
            self._alarms_reported = len(e.alarms)
            level = 1
            message = (f"dynamics change detected at t = {e.alarms[-1]:.3f} s "
                       f"({', '.join(e.alarm_joints[-1])}); covariance reset, re-identifying")
        elif self.last_error:
            level, message = 1, f"joint_states cannot be filtered: {self.last_error}"
        elif d.unexcited:
            level = 1
            message = "not excited: " + ", ".join(
                self.names[j] for j in np.flatnonzero(~d.excited))
        self.pub_diag.publish(diagnostic_array(self, "arm estimation", values, level,
                                               message))

    def _estimator_counts(self) -> dict[str, int]:
        e = self.estimator
        return {"count.gaps": e.gaps, "count.rejected_implausible": e.rejected_implausible}

    def _reset(self) -> None:
        self._t, self._q, self._tau = [], [], []
        self.estimator.reset()
        self._alarms_reported = 0

    def _save(self) -> Path:
        return save_arm_model(Path(self.p("save_path")).expanduser(),
                              self.estimator.estimate(self.version), self.p("arm"))


main = main_for(ArmEstimatorNode, __doc__ or "")

if __name__ == "__main__":
    main()
