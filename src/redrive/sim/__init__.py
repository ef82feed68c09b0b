"""Synthetic driving world: roads, agents, ego motion, and simulated sensors (L3).

``redrive.sim.scene`` is the contract between the world and the sensors; ``redrive synth`` turns a
scenario into an MCAP log.
"""
