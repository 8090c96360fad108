"""``python -m cdr_bench`` = the ``cdr-bench`` command."""

import sys

from cdr_bench.cli import main

sys.exit(main())
