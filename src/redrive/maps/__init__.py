"""The road map (layer L2): its documents and, as they come, map-file readers and indexed queries.

The value types are :mod:`redrive.types.roadmap`; :mod:`redrive.maps.document` is their JSON form.
"""
