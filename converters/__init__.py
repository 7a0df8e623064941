"""OpenDRIVE → Lanelet2 in the exact OpenDRIVE inertial frame, with an on-disk cache:
lanelets from commonroad-scenario-designer (or from any ``Converter``, e.g. the map
engine's in ``cold_maps.groundtruth``) through one Lanelet2 writer (``osm``).

Entry points: ``load_lanelet2`` (map + routing graph), ``load_lanelet_map`` (the map alone),
``convert`` (write an OSM file, get its ``LoadRecipe``), ``configure_convert`` (the
``cold-maps convert`` subcommand's arguments),
``clear_cache``; lanelet ↔ OpenDRIVE lane (``opendrive_lanes``, ``lanelets_by_opendrive_lane``),
``vehicle_lanelets`` and ``route_between`` two OpenDRIVE lanes (``converters.lanes``).
crdesigner and lanelet2 are imported lazily, inside the functions that use them. This
package never imports ``cold_maps``.
"""

from converters.api import (
    Converter,
    configure_convert,
    convert,
    crdesigner_converter,
    load_lanelet2,
    load_lanelet_map,
)
from converters.cache import clear_cache
from converters.errors import ConversionError
from converters.frame import LoadRecipe
from converters.lanes import (
    lanelets_by_opendrive_lane,
    opendrive_lanes,
    route_between,
    routing_graph,
    vehicle_lanelets,
    vehicle_rules,
)

__all__ = [
    "ConversionError",
    "Converter",
    "LoadRecipe",
    "clear_cache",
    "configure_convert",
    "convert",
    "crdesigner_converter",
    "lanelets_by_opendrive_lane",
    "load_lanelet2",
    "load_lanelet_map",
    "opendrive_lanes",
    "route_between",
    "routing_graph",
    "vehicle_lanelets",
    "vehicle_rules",
]
