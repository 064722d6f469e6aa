"""model_server_node: serves a saved model file through the model.* parameters and topic.

The model comes from the model_file parameter, or from model.* given directly (a model file
is a ROS 2 parameters file: --ros-args --params-file model.yaml). Publishes it on
dampest/model (std_msgs/String with the YAML, transient local). Setting model_file loads
another file (validated first) and bumps model.version.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from std_msgs.msg import String

from dampest_ros.core.rigid_body import ConfigError
from dampest_ros.io.yaml_io import ModelFile, load_model, model_text
from dampest_ros.ros.common import LATCHED_QOS, Param, main_for
from dampest_ros.ros.estimator_node import ModelParamNode, _prior_ok, model_params


class ModelServerNode(ModelParamNode):
    """Model server node (see the module docstring)."""

    NODE_NAME = "model_server_node"
    PARAMS = (
        Param("model_file", "", "model YAML to serve ('': the model.* parameters given at "
              "start, e.g. with --params-file)", check=_prior_ok),
    )

    def __init__(self, **kwargs: Any) -> None:
        kwargs.setdefault("automatically_declare_parameters_from_overrides", False)
        super().__init__(self.NODE_NAME, self.PARAMS, **kwargs)
        self.pub = self.create_publisher(String, "dampest/model", LATCHED_QOS)
        self.model = self._load()
        self.version = max(int(self.model.version), 1)
        self.declare_model(model_params(self.model.parameter_names, self.model.theta,
                                        self.model.theta_std, self.model.M, self.version))
        self._publish()
        self.get_logger().info(f"serving {len(self.model.parameter_names)} parameters, "
                               f"version {self.version}")

    def _load(self) -> ModelFile:
        path = str(self.p("model_file")).strip()
        if path:
            return load_model(Path(path))
        # model.* from the parameter overrides (a model file given with --params-file)
        ov = self._parameter_overrides
        try:
            import numpy as np
            return ModelFile(list(ov["model.parameter_names"].value),
                             np.array(ov["model.theta"].value),
                             np.array(ov["model.theta_std"].value),
                             np.array(ov["model.M"].value).reshape(6, 6),
                             int(ov["model.version"].value) if "model.version" in ov else 1)
        except KeyError as exc:
            raise ConfigError("model_file", f"no model_file and no {exc.args[0]} parameter; "
                              "give --params-file model.yaml or -p model_file:=...") from None

    def on_parameters(self, names: list[str]) -> None:
        if "model_file" in names and str(self.p("model_file")).strip():
            self.model = self._load()
            self.version += 1
            self.set_model(model_params(self.model.parameter_names, self.model.theta,
                                        self.model.theta_std, self.model.M, self.version))
            self._publish()
            self.get_logger().info(f"now serving {self.p('model_file')} as version "
                                   f"{self.version}")

    def _publish(self) -> None:
        m = self.model
        self.pub.publish(String(data=model_text(
            m.parameter_names, m.theta, m.theta_std, m.M, {"source": "model_server_node"},
            damping=m.damping, version=self.version)))


main = main_for(ModelServerNode, __doc__ or "")

if __name__ == "__main__":
    main()
