"""Build script for dampest_ros (colcon/ament_python and pip share it)."""

import os

from setuptools import find_packages, setup
from setuptools.command.install_scripts import install_scripts

PACKAGE_NAME = "dampest_ros"
#: Optional: several logs pooled on Dask, logs named by URL (no rosdep key: pip only).
POOL_EXTRA = ["dask", "distributed", "fsspec"]

# The single list of ROS 2 node executables: script name -> "module:function".
# Each becomes a console script (installed to lib/dampest_ros for `ros2 run`).
# test/test_package.py reads this dict with `ast`, so keep it a plain literal.
NODE_SCRIPTS: dict[str, str] = {
    "sim_node": "dampest_ros.ros.entry:sim_node",
    "preprocess_node": "dampest_ros.ros.entry:preprocess_node",
    "estimator_node": "dampest_ros.ros.entry:estimator_node",
    "arm_estimator_node": "dampest_ros.ros.entry:arm_estimator_node",
    "model_server_node": "dampest_ros.ros.entry:model_server_node",
    "controller_node": "dampest_ros.ros.entry:controller_node",
    "arm_feedforward_node": "dampest_ros.ros.entry:arm_feedforward_node",
    "recorder_node": "dampest_ros.ros.entry:recorder_node",
    "replay_node": "dampest_ros.ros.entry:replay_node",
}


#: Console scripts also installed to <prefix>/bin, which sourcing a colcon install puts on
#: PATH (lib/dampest_ros, where setup.cfg puts every console script, is for ros2 run only).
PATH_SCRIPTS = ("dampest",)


class InstallScripts(install_scripts):
    """install_scripts, then a copy of each generated console script of PATH_SCRIPTS in
    bin/ next to share/ (the same file: one entry point). A wheel (pip) generates no console
    script here, so pip installs are unchanged."""

    def run(self):
        super().run()
        bindir = os.path.join(self.get_finalized_command("install").install_data, "bin")
        for path in list(self.outfiles):
            if os.path.basename(path) in PATH_SCRIPTS:
                self.mkpath(bindir)
                target = os.path.join(bindir, os.path.basename(path))
                self.copy_file(path, target)
                self.outfiles.append(target)


def config_data_files(root="config"):
    """Everything under config/, installed to share/dampest_ros/config/... ."""
    entries = []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames.sort()
        files = sorted(os.path.join(dirpath, f) for f in filenames)
        if files:
            entries.append((os.path.join("share", PACKAGE_NAME, dirpath), files))
    return entries


setup(
    name=PACKAGE_NAME,
    version="0.1.0",
    packages=find_packages(exclude=["test*"]),
    # the shipped arm descriptions (URDF + MJCF) and the JSON Schemas of the files users
    # write, read with importlib.resources
    package_data={PACKAGE_NAME: ["data/arm/*.urdf", "data/arm/*.xml", "schemas/*.schema.json"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE_NAME]),
        ("share/" + PACKAGE_NAME, ["package.xml"]),
        # launch files (ros2 launch on a full Jazzy install); their parameter files are the
        # config/<node>.params.yaml installed by config_data_files
        ("share/" + PACKAGE_NAME + "/launch",
         ["launch/pipeline.launch.py", "launch/replay.launch.py"]),
        *config_data_files(),
    ],
    python_requires=">=3.11",
    # Pure-Python dependencies only. rclpy and the message packages come from the ROS 2
    # install (package.xml) or, for the pip-only venv, from requirements/lock.txt.
    install_requires=[
        "numpy",
        "scipy",
        "filterpy",
        "rosbags",
        "mcap",
        "mcap-ros2-support",
        "matplotlib",
        "PyYAML",
        "jsonschema",
    ],
    # pip install 'dampest_ros[pool]': several logs on Dask, logs named by fsspec URL
    extras_require={"pool": POOL_EXTRA},
    zip_safe=True,
    maintainer="dampest_ros maintainers",
    maintainer_email="dampest@example.com",
    description="Identification of underwater-vehicle hydrodynamic damping for ROS 2",
    license="Apache-2.0",
    cmdclass={"install_scripts": InstallScripts},
    entry_points={
        "console_scripts": [
            "dampest = dampest_ros.cli.main:main",
            *(f"{name} = {target}" for name, target in NODE_SCRIPTS.items()),
        ],
    },
)
