"""OpenDRIVE → Lanelet2 through commonroad-scenario-designer, in the exact OpenDRIVE
inertial frame, with an on-disk cache.

Entry points: ``load_lanelet2`` (map + routing graph), ``convert`` (write an OSM file,
get its ``LoadRecipe``), ``configure_convert``/``run_convert`` (the ``cold-maps convert`` subcommand;
``cli_convert`` runs it stand-alone),
``clear_cache``. crdesigner and lanelet2 are imported lazily, inside the functions that
use them. This package never imports ``cold_maps``.
"""

from converters.api import cli_convert, configure_convert, convert, load_lanelet2, routing_graph, run_convert
from converters.cache import clear_cache
from converters.errors import ConversionError
from converters.frame import LoadRecipe

__all__ = [
    "ConversionError",
    "LoadRecipe",
    "clear_cache",
    "cli_convert",
    "configure_convert",
    "convert",
    "load_lanelet2",
    "routing_graph",
    "run_convert",
]
