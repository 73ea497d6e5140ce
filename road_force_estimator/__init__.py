"""road_force_estimator: road profile and vertical wheel loads of a truck's front axle.

The numeric core (no ROS): :mod:`.parameters`, the vehicle model and plant, road sources,
the differentiator, the estimator and the metrics. Nodes and offline tools build on it.
"""
__version__ = '0.1.0'
