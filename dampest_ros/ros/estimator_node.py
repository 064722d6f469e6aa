"""estimator_node: recursive least squares of the damping model on live samples.

Subscribes dampest/velocity, dampest/acceleration, dampest/wrench and dampest/attitude (the
attitude for the restoring forces g(η)), matched by exact header stamp. Holds the model as the
parameters model.parameter_names, model.theta, model.theta_std, model.M (row-major, FRD),
model.version (bumped at each publish) and the term structure model.terms.* (read-only from
outside; the layout of the model file, as model_server_node has it), publishes it on dampest/model
(std_msgs/String with the model file YAML, transient local) and on /diagnostics
(diagnostic_msgs/DiagnosticArray: excitation per DOF, condition number, covariance trace,
innovation RMS, CUSUM change alarm, and every drop counter: count.* of the messages per
topic, matched, unmatched, used, rejected_nonfinite, dropped_out_of_order, rejected_outliers,
clock_jumps, lost_in_transport (messages that never reached the node: gaps in their
publication sequence numbers, e.g. a reader queue that overflowed at 10x replay),
resume_refused: the node's life totals, kept when a parameter change rebuilds the estimator
or ~/reset restarts it) at publish_rate, and once more when its input has gone quiet (no
sample for half a second of wall-clock time) after samples that are not in a publication
yet: the end of a replayed bag, whose /clock stops with it, reaches model.* whole.
Services: ~/reset (std_srvs/Trigger, back to the model it started from), ~/save (Trigger,
atomic write of the model file to save_path), ~/freeze (std_srvs/SetBool: stop or resume
updating). With resume (default) it starts from the model file at save_path with its version
when the file holds this vehicle's coefficients (else it says why, counts it and starts from
the prior); temporary files of a killed save are removed at start. The work is done by
dampest_ros.core.online.estimator.OnlineEstimator."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import (
    AccelWithCovarianceStamped,
    QuaternionStamped,
    TwistWithCovarianceStamped,
    WrenchStamped,
)
from rclpy.subscription import Subscription
from std_msgs.msg import String

from dampest_ros.core.identification.model import Model
from dampest_ros.core.identifier import DampingIdentifier
from dampest_ros.core.online.estimator import EstimatorConfig
from dampest_ros.core.online.rls.least_squares import OUTLIER_GATE
from dampest_ros.core.online.rls.update import FORGETTING_MODES
from dampest_ros.core.physics import frames
from dampest_ros.core.physics.identity import Identity
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.io.yaml_io import (
    load_model,
    load_vehicle,
    model_parameters,
    model_text,
    save_model,
)
from dampest_ros.ros.common import (
    DIAGNOSTICS_TOPIC,
    LATCHED_QOS,
    RELIABLE_QOS,
    Drain,
    EstimatorParamNode,
    Param,
    QuietFlush,
    TransportLosses,
    diagnostic_array,
    main_for,
    model_file_check,
    save_path_check,
    vehicle_check,
)
from dampest_ros.ros.convert import stamped_floats

TERM_HELP = "comma list of the vehicle's damping terms to identify, e.g. 'linear,quadratic' " \
            "('': all of the preset's terms)"


class EstimatorNode(EstimatorParamNode):
    """Estimator node (see the module docstring)."""

    NODE_NAME = "estimator_node"
    PARAMS = (
        Param("vehicle", "bluerov2_heavy", "vehicle preset: M, restoring, nominal damping "
              "(term structure and prior mean)", check=vehicle_check),
        Param("terms", "", TERM_HELP),
        Param("structure", "", "model YAML whose term structure is identified instead of the "
              "vehicle's (e.g. one written by dampest identify --select); '': the vehicle's "
              "terms (or those of terms)", check=model_file_check("structure")),
        Param("forgetting_factor", 0.999, "RLS forgetting factor λ (memory ≈ 1/(1−λ) samples)",
              low=0.9, high=1.0),
        Param("forgetting_mode", "exponential", "forget in all directions or only in the "
              "excited ones", choices=FORGETTING_MODES),
        Param("publish_rate", 1.0, "model and diagnostics publications per second (node "
              "clock: simulation time with use_sim_time)", low=0.01, high=100.0),
        Param("rate", 50.0, "sample rate of the dampest/* topics in Hz", low=1.0, high=500.0),
        Param("cutoff", 2.0, "parallel low-pass of the regression in Hz (< rate/2)", low=0.05,
              high=100.0),
        Param("chunk", 25, "samples processed at once (the estimate lags by up to chunk / rate)",
              low=1, high=1000),
        Param("outlier_gate", OUTLIER_GATE, "squared Mahalanobis distance of a sample's "
              "innovation (predicted covariance C½ΦPΦᵀC½ + V) above which the sample is "
              "rejected and counted (count.rejected_outliers); χ²(6) quantiles: 22.5 at "
              "p = 1e-3, 53.3 at p = 1e-9; 0: no gate", low=0.0, high=1e12),
        Param("prior", "", "model YAML whose theta/theta_std are the prior ('' : nominal "
              "damping of the preset with wide uncertainty)", check=model_file_check("prior")),
        Param("save_path", "dampest_model.yaml", "where ~/save writes the model YAML",
              check=save_path_check),
        Param("resume", True, "at start, continue from the model file at save_path (its θ, "
              "σ and version) when there is one for this vehicle and terms; false: start "
              "from the prior", read_only=True),
    )

    def __init__(self, keep_samples: bool = False, **kwargs: Any) -> None:
        super().__init__(self.NODE_NAME, self.PARAMS, **kwargs)
        self.keep_samples = keep_samples
        self.version = 0
        #: sample clock jumps back (matching restarted)
        self.clock_jumps = 0
        self._build()
        if self.p("resume"):
            start = self.saved_model(load_model, self._mismatch)
            if start is not None:
                self._build(start)
        self.serve_model(self._model_values())
        self.pub_model = self.create_publisher(String, "dampest/model", LATCHED_QOS)
        self.pub_diag = self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, RELIABLE_QOS)
        # raw subscriptions: the stamp and the values are read from the CDR bytes
        streams = (("velocity", TwistWithCovarianceStamped, 6),
                   ("acceleration", AccelWithCovarianceStamped, 6),
                   ("wrench", WrenchStamped, 6), ("attitude", QuaternionStamped, 4))
        # the four topics of a sample are taken together when its last one (the attitude,
        # as preprocess_node publishes them) arrives: one executor round per sample. At most
        # half the matching window per callback, so that a stream taken ahead never leaves
        # partial samples to expire; the publish timer takes what is left.
        self._samples = Drain(max(1, int(0.5 * self.estimator.cfg.max_pending * self.p("rate"))))
        #: messages lost before they reached the estimator (count.lost_in_transport)
        self.losses = TransportLosses()
        self._subs: dict[str, Subscription] = {}
        for name, kind, width in streams:
            self._subs[name] = self.create_subscription(
                kind, f"dampest/{name}",
                lambda data, info, n=name, w=width: self._on_raw(n, w, data, info),
                RELIABLE_QOS, raw=True, drain=self._samples,
                callback_group=None if name == "attitude" else self._samples.passive)
        self.start_services()
        self.quiet = QuietFlush(self, self._publish)
        self._used_at_publish = -1
        self._last_stamp = -1

    def owner(self) -> Identity:
        return self.estimator.vehicle.identity

    def _mismatch(self, m: Model) -> str | None:
        """Why model file ``m`` is not an estimate of this node's vehicle and terms (a file
        without a vehicle identity is taken with a warning)."""
        e = self.estimator
        try:
            warning = m.belongs_to(e.vehicle.identity, str(self.p("save_path")))
        except ConfigError as exc:
            return exc.reason
        if warning is not None:
            self.get_logger().warning(warning)
        if list(m.parameter_names) != list(e.names):
            missing = [n for n in e.names if n not in m.parameter_names]
            other = [n for n in m.parameter_names if n not in e.names]
            terms = (f"the structure of {self.p('structure')}" if self.p("structure") else
                     f"terms '{self.p('terms') or 'all'}'")
            return (f"its coefficients are not those of vehicle {e.vehicle.name} with {terms} "
                    f"(missing {missing}, not estimated here {other})")
        return None

    def _build(self, start: Model | None = None) -> None:
        """A new estimator from ``start`` (a resumed model file) or else the prior."""
        terms = [t.strip() for t in str(self.p("terms")).split(",") if t.strip()]
        prior = None
        if start is not None:
            prior = (start.parameter_names, start.theta, start.theta_std)
        elif str(self.p("prior")).strip():
            pm = load_model(self.p("prior"))
            prior = (pm.parameter_names, pm.theta, pm.theta_std)
        cfg = EstimatorConfig(forgetting_factor=self.p("forgetting_factor"),
                              forgetting_mode=self.p("forgetting_mode"), rate=self.p("rate"),
                              cutoff=self.p("cutoff"), chunk=self.p("chunk"),
                              outlier_gate=self.p("outlier_gate"))
        structure = load_model(self.p("structure")).damping if str(
            self.p("structure")).strip() else None
        identifier = DampingIdentifier(load_vehicle(self.p("vehicle")), terms, prior=prior,
                                       structure=structure)
        self.estimator = identifier.online(cfg, keep_samples=self.keep_samples)

    def _model_values(self) -> dict[str, Any]:
        """model.* of the current estimate, its term structure included."""
        e = self.estimator
        return model_parameters(e.to_model(self.version))

    def check_parameter(self, name: str, value: Any) -> str | None:
        try:
            if name == "structure" and str(value).strip() and str(self.p("terms")).strip():
                return "give terms or structure, not both"
            if name == "structure" and str(value).strip() and \
                    load_model(str(value)).damping is None:
                return f"structure: {value} holds no term structure (model.terms)"
            if name == "terms":
                kinds = [t.strip() for t in str(value).split(",") if t.strip()]
                from dampest_ros.core.online.estimator import restrict
                v = load_vehicle(self.p("vehicle"))
                restrict(v.damping, v.theta, kinds)
            if name == "cutoff" and not value < 0.5 * self.p("rate"):
                return f"cutoff must be below rate/2 = {0.5 * self.p('rate')} Hz, got {value}"
        except ConfigError as exc:
            return str(exc)
        return None

    # --- inputs --------------------------------------------------------------------------------

    def _on_raw(self, stream: str, width: int, data: bytes, info: dict[str, Any]) -> None:
        self.losses.seen(self._subs[stream], info)
        self.quiet.arrived()
        self._on_sample(stream, *stamped_floats(data, width))

    def _on_sample(self, stream: str, ns: int, value: np.ndarray) -> None:
        if ns < self._last_stamp - 1_000_000_000:
            self.get_logger().warning(f"sample clock jumped back by "
                                      f"{(self._last_stamp - ns) * 1e-9:.3f} s; matching "
                                      "restarted, estimate kept")
            self.estimator.restart_clock()
            self.clock_jumps += 1
            self._last_stamp = ns
        else:
            self._last_stamp = max(self._last_stamp, ns)
        # vectors FLU → FRD through the core's frame conversion (the attitude is converted
        # by the core when used)
        self.estimator.add(stream, ns, value if stream == "attitude" else
                           frames.body_twist(value))

    # --- outputs -------------------------------------------------------------------------------

    def _publish(self, force: bool = False) -> None:
        est = self.estimator
        self._samples.take()
        est.process(force=True)
        used = est.counts["used"]
        if force or used != self._used_at_publish:
            self._used_at_publish = used
            self.version += 1
            self.serve_model(self._model_values())
            self.pub_model.publish(String(data=model_text(est.to_model(self.version))))
        values = self.life_counts(est.diagnostic_values())
        values["model.version"] = self.version
        values["count.clock_jumps"] = self.clock_jumps
        values["count.lost_in_transport"] = self.losses.count
        values["count.resume_refused"] = self.resume_refused
        values["resume"] = self.resumed
        d = est.rls.diagnostics(condition=False)
        level, message = 0, "ok"
        if d.alarm:
            level, message = 1, f"damping change detected: {', '.join(d.alarm_channels)}"
        elif d.unexcited:
            level, message = 1, f"not excited: {', '.join(d.unexcited)}"
        self.pub_diag.publish(diagnostic_array(self, "damping estimation", values, level,
                                               message))

    def _estimator_counts(self) -> dict[str, int]:
        return {k: v for k, v in self.estimator.diagnostic_values().items()
                if k.startswith("count.")}

    def _reset(self) -> None:
        self.estimator.reset()

    def _save(self) -> Path:
        return save_model(Path(self.p("save_path")).expanduser(),
                          self.estimator.to_model(self.version))


main = main_for(EstimatorNode, __doc__ or "")

if __name__ == "__main__":
    main()
