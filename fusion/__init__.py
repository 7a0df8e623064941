"""fusion package (see README)."""
