"""`simulate_bag` (INTERFACES.md): not implemented yet."""
from __future__ import annotations

import sys


def main(argv: list[str] | None = None) -> int:
    print('simulate_bag: not implemented yet', file=sys.stderr)
    return 2


if __name__ == '__main__':
    sys.exit(main())
