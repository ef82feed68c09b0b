"""Geometry (layer L1): rotations, rigid transforms, boxes.  numpy + redrive.types/errors only."""
