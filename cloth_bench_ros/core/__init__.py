"""Layer 1, no ROS and no engine: scene, trajectories, metrics, codec, online evaluation."""
