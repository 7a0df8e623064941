"""The MCAP recording of a run (``recorder``): display channels for Foxglove, the exact
detections ``cold-fuse`` reads back, per-frame metrics and run metadata."""
