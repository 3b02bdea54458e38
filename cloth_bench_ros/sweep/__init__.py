"""
Sweeps: cells run on the Dask executor, their rows aggregated, the settings sweep's choice.

Modules: `study` (`cloth-bench sweep`: the cells run, one results row each), `parsing` (the
settings axes of `--mode settings`), `aggregate` (mean +- std per group, the Pareto front) and
`recommend` (the configuration to run an engine with at a rate, the deadline rule). The cells
themselves (studies/cells.py) and the results file (studies/results.py) stay in studies/: the
stress suite, the cross-reference study and hil use them too.
"""

from cloth_bench_ros.sweep.aggregate import (
    compute_per_sim_second, finite, group, pareto_front, Stat, stat,
)
from cloth_bench_ros.sweep.recommend import (
    load_recommendations, meets_deadline, recommend, recommend_for_rate, Recommendation,
    settings_results, step_ms_by_config,
)
from cloth_bench_ros.sweep.study import cells_to_run, error_row, run_cell, run_sweep, SweepPlan

__all__ = [
    'Recommendation', 'Stat', 'SweepPlan', 'cells_to_run', 'compute_per_sim_second', 'error_row',
    'finite', 'group', 'load_recommendations', 'meets_deadline', 'pareto_front', 'recommend',
    'recommend_for_rate', 'run_cell', 'run_sweep', 'settings_results', 'stat',
    'step_ms_by_config',
]
