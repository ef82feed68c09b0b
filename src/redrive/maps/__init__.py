"""The road map (layer L2): its JSON document, indexed queries and, as they come, map-file readers.

The value types are :mod:`redrive.types.roadmap`; :mod:`redrive.maps.document` is their JSON form
(schema 2); :mod:`redrive.maps.index` answers spatial queries (:class:`~redrive.maps.index.
RoadMapIndex`: lanes at points, the lane of a pose, the drivable area, the road edge, routes).
"""
