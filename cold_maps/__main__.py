"""``python -m cold_maps``: the ``cold-maps`` command."""

import sys

from cold_maps.cli.maps import main

sys.exit(main())
