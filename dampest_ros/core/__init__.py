"""Pure core of dampest_ros: model, simulation, preprocessing and estimation.

numpy, scipy and filterpy only; never imports rclpy (a test checks it).
"""
