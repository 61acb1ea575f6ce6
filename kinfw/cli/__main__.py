"""``python -m kinfw.cli``: the ``kinfw`` command."""

import sys

from kinfw.cli import main

sys.exit(main())
