"""
`cloth-bench rank`: engines fitted to a user's cloth, ranked on trials they were not fitted to.

Modules: `trials` (the trials found in a user's recordings, their floor), `study` (`run_rank`:
the folds, identifications and held-out cells), `ranking` (the ranking: divergence rate, then
the metric, paired bootstrap over trials and seeds; the cross-reference study uses it too),
`answer` (the answer per cloth and task: ranking, floor, recommendation per rate, Pareto front)
and `errors`. report/rank.py renders the answer.
"""

from cloth_bench_ros.rank.answer import deadline_ms, rank_answer
from cloth_bench_ros.rank.errors import RankError, RankInputError
from cloth_bench_ros.rank.ranking import (
    HeldOutRun, order_agreement, rank_runs, Ranked, Ranking, ranking_record, REPLICATES,
)
from cloth_bench_ros.rank.study import CELLS_FILE, DEFAULT_ENTRANTS, RankSpec, run_rank
from cloth_bench_ros.rank.trials import prepare_trials, recordings_of

__all__ = [
    'CELLS_FILE', 'DEFAULT_ENTRANTS', 'HeldOutRun', 'REPLICATES', 'RankError', 'RankInputError',
    'RankSpec', 'Ranked', 'Ranking', 'deadline_ms', 'order_agreement', 'prepare_trials',
    'rank_answer', 'rank_runs', 'ranking_record', 'recordings_of', 'run_rank',
]
