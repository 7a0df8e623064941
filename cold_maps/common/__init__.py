"""Helpers every stage uses: the progress bar (``progress``). Atomic file output is
``converters.atomic_io``, shared with the converter."""
