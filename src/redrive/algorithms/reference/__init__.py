"""Reference algorithms: simple, documented baselines for each role."""
