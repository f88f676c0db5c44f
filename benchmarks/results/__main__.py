"""``python -m benchmarks.results [--check]``: :func:`benchmarks.results.doc.main`."""

import sys

from benchmarks.results.doc import main

sys.exit(main())
