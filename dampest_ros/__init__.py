"""dampest_ros: identification of underwater-vehicle hydrodynamic damping for ROS 2."""

__version__ = "0.1.0"
