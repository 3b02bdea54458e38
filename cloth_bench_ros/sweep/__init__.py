"""
Sweeps: cells run on the Dask executor, their rows aggregated, the settings sweep's choice.

Modules: `study` (`cloth-bench sweep`: `run_sweep`, `SweepPlan`, one results row per cell),
`parsing` (the settings axes of `--mode settings`), `aggregate` (mean +- std per group, the
Pareto front) and `recommend` (the configuration to run an engine with at a rate, by the deadline
rule). The cells themselves (studies/cells.py) and the results file (studies/results.py) stay in
studies/: the stress suite, the cross-reference study and hil use them too. As in hil/, the
package root imports only the light modules (the analysis), so that the report and hil read
results without loading the executor.
"""

from cloth_bench_ros.sweep.aggregate import (
    compute_per_sim_second, finite, group, pareto_front, Stat, stat,
)
from cloth_bench_ros.sweep.recommend import (
    load_recommendations, meets_deadline, recommend_for_rate, Recommendation, settings_results,
    step_ms_by_config,
)

__all__ = [
    'Recommendation', 'Stat', 'compute_per_sim_second', 'finite', 'group',
    'load_recommendations', 'meets_deadline', 'pareto_front', 'recommend_for_rate',
    'settings_results', 'stat', 'step_ms_by_config',
]
