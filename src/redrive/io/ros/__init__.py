"""ROS messages: the type store (with the ``.msg`` files redrive ships), ROS 1 / CDR encoding and
deserialising, and the decoders from ROS messages to the data model."""
