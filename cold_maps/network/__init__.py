"""The road network as the vehicles see it: the driving-lane graph (``lane_graph``),
routing over it (``routing``), routes as continuous borders (``route``) and lane strips
sampled along a route (``lane_strip``). World frame = OpenDRIVE inertial frame, metres."""
