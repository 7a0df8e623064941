"""The bundled scenario maps (OpenDRIVE files written by tools/make_maps.py), installed as
package data ``cold_maps.maps`` and found through ``importlib.resources``."""
