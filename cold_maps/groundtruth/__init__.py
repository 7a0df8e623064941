"""Ground truth from the Lanelet2 map converted from the same OpenDRIVE file: measuring
lanes against it (``meter``, over ``gt_matching``) and checking the converted map against
the engine's own borders (``check``, ``cold-maps check``)."""
