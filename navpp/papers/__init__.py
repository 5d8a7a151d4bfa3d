"""The papers' benchmarks: each paper's experiment re-run with the filters that process logs.

One module per experiment: :mod:`.tracking` (paper 001 section 4.1), :mod:`.xpn` (paper 001
section 4.2), :mod:`.sins` (paper 002 section 4), :mod:`.bearing` and :mod:`.turn` (paper 003),
:mod:`.table5_real` (paper 001's Table 5 protocol on the real logs).  Importing this package imports
them, and each registers its run function in :data:`.registry.BENCHMARKS` under the name
``navpp bench NAME`` takes.  :mod:`.registry` (results, the table, running and printing),
:mod:`.filter_spec` (a filter built from ``name[key=value]``), :mod:`.montecarlo` (the small
benchmarks' runs), :mod:`.vce_factors` and :mod:`.angles` import none of the experiments.
"""

from . import bearing, sins, table5_real, tracking, turn, xpn  # noqa: F401  (register the benchmarks)
from .filter_spec import make_bench_filter, parse_filter_spec
from .registry import (
           BENCHMARKS,
           Benchmark,
           BenchResult,
           Row,
           expected_cpu_s,
           format_result,
           get_benchmark,
           run_benchmark,
)

__all__ = ["BENCHMARKS", "BenchResult", "Benchmark", "Row", "expected_cpu_s", "format_result", "get_benchmark",
           "make_bench_filter", "parse_filter_spec", "run_benchmark"]
