"""Calibrated cameras: ``Camera``, ``Rig`` and ground planes, rig files (YAML/JSON, OpenCV FileStorage, Tsai), their
checks and the cameras' device structs."""
