"""Fixtures that write real files for tests and benchmarks (nothing in redrive's core imports
this package): :func:`redrive.testing.demo_log.write_demo_bag` writes a small multi-sensor ROS 1
bag with the real rosbags writer."""
