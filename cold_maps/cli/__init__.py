"""The command-line tools: ``cold-maps`` (``maps``), ``cold-eval`` (``evaluate``) and
``cold-fuse`` (``fuse``), with their shared conventions (``common``)."""
