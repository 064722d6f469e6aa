"""ROS 2 nodes (rclpy): message and parameter conversion only, one node per module."""

import os

# One BLAS thread: with two, a small blocked update took 25x longer (docs/architecture.md §6). Set
# before numpy is first imported by the nodes.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
