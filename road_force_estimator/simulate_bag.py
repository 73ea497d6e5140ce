"""`simulate_bag`: see ../shared/design/INTERFACES.md. Not implemented yet (its issue is open)."""
from __future__ import annotations

import sys


def main(argv: list[str] | None = None) -> int:
    print('simulate_bag: not implemented yet', file=sys.stderr)
    return 2


if __name__ == '__main__':
    sys.exit(main())
