"""``cold-eval``: batch evaluation (not built yet)."""

from __future__ import annotations

import sys


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``cold-eval``: says it is not built yet and exits 2."""
    print("cold-eval: not built yet (see the open issue 'cold-eval')", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main())
