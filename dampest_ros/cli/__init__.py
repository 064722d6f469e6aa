"""dampest_ros.cli"""
