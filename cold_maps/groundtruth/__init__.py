"""Ground truth: the Lanelet2 map built from the engine's own borders and lane graph
(``lanelet2_from_engine``, with ``road_rules`` for road types and regulations) or
converted by crdesigner; measuring lanes against it (``meter``, over ``gt_matching``) and
checking a converted map against the engine's borders (``check``, ``cold-maps check``)."""
