"""A robot's own recording: parse it with a mapping (``mapping``, ``recording``), add the
rigid-body terms of its URDF (``dynamics``, with Pinocchio) and write a long-format log
(``importing``)."""
