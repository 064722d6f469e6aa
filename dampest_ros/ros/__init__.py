"""ROS 2 nodes (rclpy): message and parameter conversion only, one node per module."""

from dampest_ros.threads import one_blas_thread

# One BLAS thread: with two, a small blocked update took 25x longer (docs/architecture.md §6). Set
# before numpy is first imported by the nodes.
one_blas_thread()
