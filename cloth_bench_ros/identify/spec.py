"""What an identification fits, against what and how: `IdentifySpec`, the study's one input."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

from cloth_bench_ros.command_options import COMMAND_FLAGS
from cloth_bench_ros.engines.settle import FULL
from cloth_bench_ros.options import FLAGS, OPTIONS

AUTO = 0  # trials: the budget chosen from the convergence curve (identify.curve)
DEFAULT_TRIALS = FLAGS['trials'].default
DEFAULT_SPAN = 10.0
OBJECTIVES = ('cd', 'hd')  # the metrics an identification can minimise


@dataclass
class IdentifySpec:
    """What to identify, against what, how; checked by `check()`."""

    engine: str
    cloth: str
    primitive: str
    bag: Path
    output: Path
    sampler: str = FLAGS['sampler'].default
    trials: int = DEFAULT_TRIALS  # per sampler; AUTO: chosen by doubling (see budget_reached)
    objective: str = COMMAND_FLAGS['objective'].default
    params: Sequence[str] = ()
    seed: int = 0
    rate_hz: float = OPTIONS['rate_hz'].default
    grid: tuple[int, int] | None = None
    fixed: dict = field(default_factory=dict)  # overrides on top of the preset, not fitted
    span: float = DEFAULT_SPAN
    max_frames: int | None = None
    batch: int | None = None  # trials in flight (default: the cluster's worker threads)
    validate_seeds: int = COMMAND_FLAGS['validate_seeds'].default
    bag_dir: Path | None = None  # other trials' bags for validation (default: the bag's directory)
    also: tuple[str, ...] = ()  # more training bags: the objective is the mean over all of them
    # or prune, coarse: multi-fidelity (identify/fidelity.py)
    fidelity: str = FLAGS['fidelity'].default
    cloth_size: tuple[float, float] | None = None  # (W, L) m; None: the benchmark's 0.5 x 0.7
    cloth_mass: float | None = None  # kg, given: not fitted unless named in `params`
    settle: str = FULL  # the settle phase (engines/settle.py): full (the paper's) or fast
    pool: tuple[str, ...] = ()  # rank's: every trial of the group, scored by each simulation
    shared: Path | None = None  # rank's: the folds' simulations (identify.shared_simulations)
    task: str = ''  # a task file for bags without their own (objective.TASK_IN_BAG)
    cloth_mesh: str = ''  # --cloth-mesh; '': the grid
    gripper_frames: str = ''  # recorded only (the task file holds the motion they gave)
    table_z: float | None = None
