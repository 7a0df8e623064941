"""OpenDRIVE reader and vectorised geometry (one module per OpenDRIVE element)."""
