"""wptrack: particle-filter 3D object tracking from calibrated cameras on NVIDIA Warp."""

from __future__ import annotations

import logging

__version__ = "0.1.0"

logging.getLogger(__name__).addHandler(logging.NullHandler())
