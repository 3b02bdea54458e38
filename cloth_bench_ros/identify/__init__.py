"""
Parameter identification: an engine's parameters fitted to recorded trials with Optuna.

Modules: `spec` (`IdentifySpec`: what to fit, against what, how), `study` (`identify`: the
samplers, the budget, the journal), `objective` (one scored simulation of a trial's parameters),
`problem` (what a journal was fitted to, and its check), `fidelity` (the coarse-mesh pruner),
`curve` (convergence, the auto budget, importance), `output` (the summary, the fitted preset, the
held-out validation), `shared_simulations` (simulations the folds of a ranking share) and
`errors`. As in hil/, the
package root imports only the light modules: the others load Optuna, Dask or the engines, and
are imported by name where they are used.
"""

from cloth_bench_ros.identify.errors import ProblemChanged
from cloth_bench_ros.identify.spec import IdentifySpec

__all__ = ['IdentifySpec', 'ProblemChanged']
