"""`python -m cloth_bench_ros.cli`: the same as `cloth-bench`."""

from cloth_bench_ros.cli import main

raise SystemExit(main())
