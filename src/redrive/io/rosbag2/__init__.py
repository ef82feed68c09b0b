"""ROS 2 bags (a folder with ``metadata.yaml``; sqlite3 or mcap storage) and their salvage."""
