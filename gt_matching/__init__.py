"""gt_matching package (see README)."""
