"""ROS 2 nodes: thin rclpy nodes over the core, engine and data layers; each has a main()."""
