"""File input and output, without rclpy.

- :mod:`dampest_ros.io.cdr`: fixed-layout CDR encode/decode of the measurement series (numpy).
- :mod:`dampest_ros.io.bag`: rosbag2 bags (MCAP, SQLite3) via rosbags: ``write_bag``,
  ``read_bag``, ``bag_summary``.
- :mod:`dampest_ros.io.csv`: the seed paper's CSV format (FRD body frame) and column maps.
- :mod:`dampest_ros.io.csv_folder`: a folder of per-topic CSV files (``rostopic echo -p``)
  read as a bag; :mod:`dampest_ros.io.csv_table`: numeric columns by name, time units.
- :mod:`dampest_ros.io.yaml_io`: vehicle presets and the model file (a ROS 2 parameters file).
"""
