"""model_server_node: serves a saved model file through the model.* parameters and topic.

The model comes from the model_file parameter, or from model.* given directly (a model file
is a ROS 2 parameters file: --ros-args --params-file model.yaml). Its parameters are those
of the file: model.parameter_names, theta, theta_std, M, version, sign_convention, the
term structure model.terms.* (so that dampest_ros.client evaluates cross, added-mass and
residual terms too) and, when the file has them, model.M_A and the added-mass switches
model.added_mass_terms.{inertial,coriolis,munk} (and coriolis_mask, 36 ints, when single
entries of C_A are zeroed), and model.identified (per coefficient:
did the data determine it) with model.held.{names,reasons} for those that hold their prior.
Publishes it on dampest/model (std_msgs/String with the YAML, transient local). Setting
model_file loads another file (validated first: a file no reader takes, e.g. a non-finite
theta, is rejected with the reason and the served model stays) and bumps model.version. A
model refused at start ends the node with one logged error and exit status 2.

An arm model file (model.kind arm_base_parameters: dampest arm identify --out,
arm_estimator_node's ~/save) is served with arm_estimator_node's contract: model.kind,
model.arm, model.joint_names, model.parameter_names, model.theta, model.theta_std,
model.identified, model.mapping, model.coulomb_width, model.version and model.identity.*,
published on dampest/arm_model (what dampest_ros.client.ArmModelClient reads).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

from std_msgs.msg import String

from dampest_ros.core.arm.online import ArmEstimate
from dampest_ros.core.identification.model import Model
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.io.arm import (
    ARM_MODEL_KIND,
    ArmDataError,
    arm_model_from_parameters,
    arm_model_parameters,
    arm_model_text,
    is_arm_model_file,
    read_arm_model,
)
from dampest_ros.io.yaml_io import (
    load_model,
    model_from_parameters,
    model_parameters,
    model_text,
)
from dampest_ros.ros.common import (
    LATCHED_QOS,
    ModelParamNode,
    Param,
    main_for,
    model_file_check,
)

#: An arm's model as served: the estimate and the arm it names (model.arm).
ArmFile = tuple[ArmEstimate, str]


def _read(path: str) -> Model | ArmFile:
    """The model of a vehicle or arm model file (ConfigError, ArmDataError: why not)."""
    return read_arm_model(path) if is_arm_model_file(path) else load_model(Path(path))


def _file_check(value: object) -> str | None:
    """model_file's check: the reason the file is refused as an arm or vehicle model."""
    if str(value).strip() and is_arm_model_file(str(value)):
        try:
            read_arm_model(str(value))
        except ArmDataError as exc:
            return f"model_file: {exc}"
        return None
    return model_file_check("model_file")(value)


class ModelServerNode(ModelParamNode):
    """Model server node (see the module docstring)."""

    NODE_NAME = "model_server_node"
    PARAMS = (
        Param("model_file", "", "model YAML to serve ('': the model.* parameters given at "
              "start, e.g. with --params-file)", check=_file_check),
    )

    def __init__(self, **kwargs: Any) -> None:
        kwargs.setdefault("automatically_declare_parameters_from_overrides", False)
        super().__init__(self.NODE_NAME, self.PARAMS, **kwargs)
        self.pub = self.create_publisher(String, "dampest/model", LATCHED_QOS)
        self.pub_arm = self.create_publisher(String, "dampest/arm_model", LATCHED_QOS)
        self.model = self._load()
        self.version = max(int(self._held().version), 1)
        self._serve()
        self.get_logger().info(f"serving {len(self._held().parameter_names)} parameters, "
                               f"version {self.version}")

    def _held(self) -> Model | ArmEstimate:
        """The vehicle model or the arm estimate served."""
        return self.model if isinstance(self.model, Model) else self.model[0]

    def _load(self) -> Model | ArmFile:
        path = str(self.p("model_file")).strip()
        if path:
            return _read(path)
        # model.* from the parameter overrides (a model file given with --params-file)
        ov = {k: v.value for k, v in self._parameter_overrides.items()}
        if "model.parameter_names" not in ov:
            raise ConfigError("model_file", "no model_file and no model.parameter_names "
                              "parameter; give --params-file model.yaml or -p model_file:=...")
        if ov.get("model.kind") == ARM_MODEL_KIND:
            return arm_model_from_parameters(ov)
        return model_from_parameters(ov)

    def _serve(self) -> None:
        """Hold the model in model.* (the names may change with the file), publish it."""
        source = {"source": "model_server_node"}
        if isinstance(self.model, Model):
            m = replace(self.model, version=self.version)
            self.serve_model(model_parameters(m))
            self.pub.publish(String(data=model_text(replace(m, extra=source))))
            return
        est, arm = replace(self.model[0], version=self.version), self.model[1]
        self.serve_model(arm_model_parameters(est, arm))
        self.pub_arm.publish(String(data=arm_model_text(est, arm, source)))

    def on_parameters(self, names: list[str]) -> None:
        if "model_file" in names and str(self.p("model_file")).strip():
            self.model = self._load()
            self.version += 1
            self._serve()
            self.get_logger().info(f"now serving {self.p('model_file')} as version "
                                   f"{self.version}")


main = main_for(ModelServerNode, __doc__ or "")

if __name__ == "__main__":
    main()
