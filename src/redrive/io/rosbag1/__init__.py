"""ROS 1 bags (format 2.0): the reader, its index and record layer, and the scan of damaged bags."""
