"""converters package (see README)."""
