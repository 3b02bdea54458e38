"""
Parameter identification: an engine's parameters fitted to recorded trials with Optuna.

Modules: `study` (`identify`, `IdentifySpec`: the samplers, the budget, the journal), `objective`
(one scored simulation of a trial's parameters), `problem` (what a journal was fitted to, and
its check), `fidelity` (the coarse-mesh pruner), `curve` (convergence, the auto budget,
importance), `output` (the summary, the fitted preset, the held-out validation),
`shared_simulations` (simulations the folds of a ranking share) and `errors`.
"""

from cloth_bench_ros.identify.errors import ProblemChanged
from cloth_bench_ros.identify.objective import (
    bag_clouds, bag_task, evaluate, OBJECTIVES, TASK_IN_BAG, Trial, trial_of,
)
from cloth_bench_ros.identify.problem import resolved_device, simulated_model
from cloth_bench_ros.identify.shared_simulations import (
    pool_cells, SharedSimulations, split_pooled,
)
from cloth_bench_ros.identify.study import (
    AUTO, identify, IdentifySpec, JOURNAL_FILE, SUMMARY_FILE, TRIALS_FILE,
)

__all__ = [
    'AUTO', 'IdentifySpec', 'JOURNAL_FILE', 'OBJECTIVES', 'ProblemChanged', 'SUMMARY_FILE',
    'SharedSimulations', 'TASK_IN_BAG', 'TRIALS_FILE', 'Trial', 'bag_clouds', 'bag_task',
    'evaluate', 'identify', 'pool_cells', 'resolved_device', 'simulated_model', 'split_pooled',
    'trial_of',
]
