"""OpenDRIVE reader and vectorised geometry (one module per OpenDRIVE element).

``load_opendrive(path)`` reads a file into the immutable model (``model``);
``sampling`` and ``projection`` evaluate it in the OpenDRIVE inertial frame.
"""

from cold_maps.opendrive.errors import OpenDriveError
from cold_maps.opendrive.parser import load_opendrive, parse_opendrive

__all__ = ["OpenDriveError", "load_opendrive", "parse_opendrive"]
