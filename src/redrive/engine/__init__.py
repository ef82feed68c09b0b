"""The Orchestration Engine (L5): the perception → planning → control stage graph, run modes and
the Mode Manager."""
