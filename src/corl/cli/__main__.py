"""``python -m corl.cli``: the ``corl`` command."""

import sys

from corl.cli import main

if __name__ == "__main__":  # imported (by the API reference, say), it runs nothing
    sys.exit(main())
