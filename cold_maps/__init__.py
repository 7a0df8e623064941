"""cold-maps: collective lane detection (CoLD) on real road maps.

The OpenDRIVE map engine (``cold_maps.opendrive``), lane graph and routing, the lane
sensor, drives, evaluation and the command-line tools. Builds on ``fusion``,
``converters`` and ``gt_matching``, which never import this package.
"""

__version__ = "0.1.0"
