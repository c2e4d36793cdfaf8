"""lidarfield: discrepancy-vector fields between registered lidar scans, and hypotheses that
explain them."""

__version__ = "0.1.0"
