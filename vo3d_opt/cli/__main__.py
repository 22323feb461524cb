"""``python -m vo3d_opt.cli``: the ``vo3d`` command."""

import sys

from vo3d_opt.cli import main

sys.exit(main())
