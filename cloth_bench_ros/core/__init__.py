"""Layer 1, no ROS and no engine: scene, trajectories, metrics, PointCloud2 codec, online evaluation."""
