"""Helpers every stage's outputs use: atomic file output (``atomic_io``) and the progress
bar (``progress``)."""
