"""
`cloth-bench rank`: engines fitted to a user's cloth, ranked on trials they were not fitted to.

Modules: `trials` (the trials found in a user's recordings, their floor), `study` (`run_rank`:
the folds, identifications and held-out cells), `ranking` (divergence rate, then the metric,
paired bootstrap over trials and seeds; the cross-reference study uses it too), `answer` (the
answer per cloth and task: ranking, floor, recommendation per rate, Pareto front) and `errors`;
report/rank.py renders the answer. As in hil/, the package root imports only the light modules
(the statistics and the answer), so that the report reads rank.json without loading the study.
"""

from cloth_bench_ros.rank.answer import deadline_ms, rank_answer
from cloth_bench_ros.rank.errors import RankError, RankInputError
from cloth_bench_ros.rank.ranking import (
    HeldOutRun, order_agreement, rank_runs, Ranked, Ranking, ranking_record, REPLICATES,
)

__all__ = [
    'HeldOutRun', 'REPLICATES', 'RankError', 'RankInputError', 'Ranked', 'Ranking',
    'deadline_ms', 'order_agreement', 'rank_answer', 'rank_runs', 'ranking_record',
]
