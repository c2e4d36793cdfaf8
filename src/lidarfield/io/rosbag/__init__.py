"""ROS bags: opening and indexing a bag, its PointCloud2 messages as scans, poses from /tf or
odometry topics, and writing bags (for tests and examples)."""
