"""estimator_node: recursive least squares of the damping model on live samples.

Subscribes dampest/velocity, dampest/acceleration, dampest/wrench and dampest/attitude (the
attitude for the restoring forces g(η)), matched by exact header stamp. Holds the model as the
parameters model.parameter_names, model.theta, model.theta_std, model.M (row-major, FRD),
model.version (bumped at each publish) and the term structure model.terms.* (read-only from
outside; the layout of the model file, as model_server_node has it), publishes it on dampest/model
(std_msgs/String with the model file YAML, transient local) and diagnostics
(diagnostic_msgs/DiagnosticArray: excitation per DOF, condition number, covariance trace,
innovation RMS, CUSUM change alarm, samples rejected by the outlier gate) at publish_rate.
Services: ~/reset (std_srvs/Trigger, back to the prior), ~/save (Trigger, atomic write of the
model file to save_path), ~/freeze (std_srvs/SetBool: stop or resume updating). The work is
done by dampest_ros.core.estimator.OnlineEstimator.
"""

from __future__ import annotations

import threading
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
from rclpy.parameter import Parameter
from std_msgs.msg import String
from std_srvs.srv import SetBool, Trigger

from dampest_ros.core import frames
from dampest_ros.core.estimator import EstimatorConfig, OnlineEstimator
from dampest_ros.core.rigid_body import ConfigError
from dampest_ros.core.rls import FORGETTING_MODES, OUTLIER_GATE
from dampest_ros.io.yaml_io import load_model, load_vehicle, model_parameters
from dampest_ros.ros.common import (
    LATCHED_QOS,
    RELIABLE_QOS,
    Drain,
    Param,
    ParamNode,
    diagnostic_array,
    main_for,
)
from dampest_ros.ros.convert import stamped_floats
from dampest_ros.ros.sim_node import _vehicle_ok

TERM_HELP = "comma list of the vehicle's damping terms to identify, e.g. 'linear,quadratic' " \
            "('': all of the preset's terms)"


def _prior_ok(value: Any) -> str | None:
    if not str(value).strip():
        return None
    try:
        load_model(str(value))
    except (ConfigError, FileNotFoundError, ValueError, OSError) as exc:
        return f"prior: {exc}"
    return None


def _save_ok(value: Any) -> str | None:
    parent = Path(str(value)).expanduser().resolve().parent
    if not str(value).strip():
        return "save_path must not be empty"
    if not parent.is_dir():
        return f"save_path: directory {parent} does not exist"
    return None


class ModelParamNode(ParamNode):
    """A node that holds the model in the read-only (from outside) model.* parameters."""

    def __init__(self, name: str, specs: Any, **kwargs: Any) -> None:
        self._internal = threading.local()
        self._served: dict[str, Any] = {}
        super().__init__(name, specs, **kwargs)

    def serve_model(self, values: dict[str, Any]) -> None:
        """Hold ``values`` in model.* (dotted name → value, as
        :func:`dampest_ros.io.yaml_io.model_parameters` gives them): declare the new names,
        undeclare those gone (the terms' names change with the structure), set the changed
        values."""
        for name in set(self._served) - set(values):
            self.undeclare_parameter(name)
        added = [Parameter(n, value=v) for n, v in values.items() if n not in self._served]
        changed = [Parameter(n, value=v) for n, v in values.items()
                   if n in self._served and self._served[n] != v]
        if added:
            self.declare_model(added)
        if changed:
            self.set_model(changed)
        self._served = values

    def declare_model(self, params: list[Parameter]) -> None:
        """Declare model.* (read-only from outside: see :meth:`_check_parameters`)."""
        from rcl_interfaces.msg import ParameterDescriptor
        self._internal.on = True
        try:
            for prm in params:
                self.declare_parameter(prm.name, prm.value, ParameterDescriptor(
                    description="identified damping model (docs/architecture.md §3); set by "
                                "this node"))
        finally:
            self._internal.on = False

    def set_model(self, params: list[Parameter]) -> None:
        """Set model.* (allowed only from here)."""
        self._internal.on = True
        try:
            result = self.set_parameters_atomically(params)
        finally:
            self._internal.on = False
        if not result.successful:
            self.get_logger().error(f"could not set the model parameters: {result.reason}")

    def _check_parameters(self, params: list[Parameter]) -> Any:
        from rcl_interfaces.msg import SetParametersResult
        if not getattr(self._internal, "on", False):
            for prm in params:
                if prm.name.startswith("model."):
                    return SetParametersResult(
                        successful=False, reason=f"{prm.name} is read-only: the model is set by "
                        f"{self.get_name()} itself")
        return super()._check_parameters(params)


class EstimatorNode(ModelParamNode):
    """Estimator node (see the module docstring)."""

    NODE_NAME = "estimator_node"
    PARAMS = (
        Param("vehicle", "bluerov2_heavy", "vehicle preset: M, restoring, nominal damping "
              "(term structure and prior mean)", check=_vehicle_ok),
        Param("terms", "", TERM_HELP),
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
              "damping of the preset with wide uncertainty)", check=_prior_ok),
        Param("save_path", "dampest_model.yaml", "where ~/save writes the model YAML",
              check=_save_ok),
    )

    def __init__(self, keep_samples: bool = False, **kwargs: Any) -> None:
        super().__init__(self.NODE_NAME, self.PARAMS, **kwargs)
        self.keep_samples = keep_samples
        self.version = 0
        self._build()
        self.serve_model(self._model_values())
        self.pub_model = self.create_publisher(String, "dampest/model", LATCHED_QOS)
        self.pub_diag = self.create_publisher(DiagnosticArray, "diagnostics", RELIABLE_QOS)
        # raw subscriptions: the stamp and the values are read from the CDR bytes
        streams = (("velocity", TwistWithCovarianceStamped, 6),
                   ("acceleration", AccelWithCovarianceStamped, 6),
                   ("wrench", WrenchStamped, 6), ("attitude", QuaternionStamped, 4))
        # the four topics of a sample are taken together when its last one (the attitude,
        # as preprocess_node publishes them) arrives: one executor round per sample. At most
        # half the matching window per callback, so that a stream taken ahead never leaves
        # partial samples to expire; the publish timer takes what is left.
        self._samples = Drain(max(1, int(0.5 * self.estimator.cfg.max_pending * self.p("rate"))))
        for name, kind, width in streams:
            self.create_subscription(
                kind, f"dampest/{name}",
                lambda data, n=name, w=width: self._on_sample(n, *stamped_floats(data, w)),
                RELIABLE_QOS, raw=True, drain=self._samples,
                callback_group=None if name == "attitude" else self._samples.passive)
        self.create_service(Trigger, "~/reset", self._srv_reset)
        self.create_service(Trigger, "~/save", self._srv_save)
        self.create_service(SetBool, "~/freeze", self._srv_freeze)
        self._timer = self.create_timer(1.0 / self.p("publish_rate"), self._publish)
        self._used_at_publish = -1
        self._last_stamp = -1

    def _build(self) -> None:
        terms = [t.strip() for t in str(self.p("terms")).split(",") if t.strip()]
        prior = None
        if str(self.p("prior")).strip():
            pm = load_model(self.p("prior"))
            prior = (pm.parameter_names, pm.theta, pm.theta_std)
        cfg = EstimatorConfig(forgetting_factor=self.p("forgetting_factor"),
                              forgetting_mode=self.p("forgetting_mode"), rate=self.p("rate"),
                              cutoff=self.p("cutoff"), chunk=self.p("chunk"),
                              outlier_gate=self.p("outlier_gate"))
        self.estimator = OnlineEstimator(load_vehicle(self.p("vehicle")), terms, cfg, prior,
                                         keep_samples=self.keep_samples)

    def _model_values(self) -> dict[str, Any]:
        """model.* of the current estimate, its term structure included."""
        e = self.estimator
        return model_parameters(e.names, e.theta, e.theta_std, e.M, damping=e.model,
                                version=self.version, **e.added_mass_kwargs())

    def check_parameter(self, name: str, value: Any) -> str | None:
        try:
            if name == "terms":
                kinds = [t.strip() for t in str(value).split(",") if t.strip()]
                from dampest_ros.core.estimator import restrict
                v = load_vehicle(self.p("vehicle"))
                restrict(v.damping, v.theta, kinds)
            if name == "cutoff" and not value < 0.5 * self.p("rate"):
                return f"cutoff must be below rate/2 = {0.5 * self.p('rate')} Hz, got {value}"
        except ConfigError as exc:
            return str(exc)
        return None

    def on_parameters(self, names: list[str]) -> None:
        if names == ["forgetting_factor"]:
            self.estimator.rls.set_forgetting_factor(self.p("forgetting_factor"))
            self.get_logger().info(f"forgetting factor {self.p('forgetting_factor')}")
            return
        if "publish_rate" in names:
            self._timer.cancel()
            self._timer = self.create_timer(1.0 / self.p("publish_rate"), self._publish)
        if set(names) & {"vehicle", "terms", "forgetting_factor", "forgetting_mode", "rate",
                         "cutoff", "chunk", "prior", "outlier_gate"}:
            self._build()
            self.get_logger().info(f"estimator restarted from the prior ({', '.join(names)} "
                                   "changed)")
            self._publish(force=True)

    # --- inputs --------------------------------------------------------------------------------

    def _on_sample(self, stream: str, ns: int, value: np.ndarray) -> None:
        if ns < self._last_stamp - 1_000_000_000:
            self.get_logger().warning(f"sample clock jumped back by "
                                      f"{(self._last_stamp - ns) * 1e-9:.3f} s; matching "
                                      "restarted, estimate kept")
            self.estimator.restart_clock()
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
            self.pub_model.publish(String(data=est.text(self.version)))
        values = est.diagnostic_values()
        values["model.version"] = self.version
        d = est.rls.diagnostics(condition=False)
        level, message = 0, "ok"
        if d.alarm:
            level, message = 1, f"damping change detected: {', '.join(d.alarm_channels)}"
        elif d.unexcited:
            level, message = 1, f"not excited: {', '.join(d.unexcited)}"
        self.pub_diag.publish(diagnostic_array(self, "dampest estimator", values, level,
                                               message))

    def _srv_reset(self, _: Trigger.Request, res: Trigger.Response) -> Trigger.Response:
        self.estimator.reset()
        self._publish(force=True)
        res.success, res.message = True, f"reset to the prior (model version {self.version})"
        return res

    def _srv_save(self, _: Trigger.Request, res: Trigger.Response) -> Trigger.Response:
        try:
            path = self.estimator.save(Path(self.p("save_path")).expanduser(), self.version)
        except (OSError, ValueError) as exc:
            res.success, res.message = False, f"could not save: {exc}"
            return res
        res.success, res.message = True, f"saved model version {self.version} to {path}"
        return res

    def _srv_freeze(self, req: SetBool.Request, res: SetBool.Response) -> SetBool.Response:
        self.estimator.rls.frozen = bool(req.data)
        res.success = True
        res.message = "frozen: estimate held" if req.data else "updating"
        return res


main = main_for(EstimatorNode, __doc__ or "")

if __name__ == "__main__":
    main()
