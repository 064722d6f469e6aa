"""Pure core of dampest_ros: model, simulation, preprocessing and estimation.

numpy, scipy and filterpy only; never imports rclpy (a test checks it), nor io, cli or ros.
Grouped into rooms, each importing only from the rooms below it (``make lint`` checks it;
docs/architecture.md §2):

- :mod:`.arm`, :mod:`.gap`, :mod:`.identifier` — the arm; the sim-to-real gap; the one
  estimator object over batch and online;
- :mod:`.online` — causal preprocessing, the recursive regression and RLS;
- :mod:`.identification`, :mod:`.simulation` — batch identification; the simulators;
- :mod:`.signals` — from sensor messages to samples;
- :mod:`.physics` — Fossen's equation and the vehicle.
"""
