"""Benchmarks (``make bench``): speed and memory of the simulator, the offline identification
and the online pipeline.

Each measurement runs in a fresh subprocess so that its peak resident memory is its own.
Prints a table; ``--hours`` sets the length of the long identification bags, ``--only`` picks
groups of rows. The online rows (ROS 2 nodes; the environment's ROS_DOMAIN_ID, localhost only):

- ``live``: sim_node → preprocess_node → estimator_node → controller_node (shadow mode) in
  one process on one SingleThreadedExecutor, as ``dampest live`` builds them, BlueROV2 Heavy,
  protocol B, flown flat out (the sim asks for 1000× real time and slows down to what the
  executor sustains, at most ``max_lag`` simulated seconds per tick); the figure is simulated
  over wall-clock time, with every message that did not arrive counted;
- ``estimator``: CPU per sample of estimator_node in its own process against a bare rclpy
  node (the same four dampest/* subscriptions, callbacks that do nothing) in another, both
  receiving the same samples from a third process at 10× real time;
- ``recorder``: recorder_node in its own process records the sim topic set while sim_node
  runs at 20× real time: messages lost and the recorder's CPU per message; then
  ``--kills`` recordings killed with SIGKILL at a random moment and recovered with reindex:
  the share of the messages the recorder had received before the kill that the bag keeps
  (the recorder's own loss; its node counts them in a shared memory page), and the share of
  those published before the kill (messages still in the middleware's queues included),
  min / median of each.

The start-up rows (``startup``): wall-clock time of ``dampest --help`` and of every
``dampest CMD --help`` (median of 5 runs of the console script), and how soon ``dampest
record`` records: a publisher sends imu/data at 100 Hz, ``dampest record -o BAG imu/data`` is
started, and the figure is the time from starting the process to the receive stamp of the
first message in the bag (the recorder stamps messages with the system clock on receipt), so
it holds the interpreter start, the imports, the node, discovery and the first subscription.
"""
