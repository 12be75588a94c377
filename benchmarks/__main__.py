"""`python -m benchmarks [--quick] [--out BENCHMARKS.md]`: run the benchmark suite (see :mod:`benchmarks.run`)."""

from benchmarks.run import main

raise SystemExit(main())
