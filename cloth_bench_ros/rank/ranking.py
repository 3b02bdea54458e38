"""
A ranking's statistics: engines scored on the same held-out trials and seeds, paired bootstrap.

Every engine ran on the same units: a held-out trial and a seed (the seed perturbs the cloth's
start alike in every engine). A bootstrap replicate draws the trials with replacement, then
within each drawn trial its seeds with replacement, and every engine takes that same draw
(paired, two levels: the trials are the sample, the seeds a second level within each).

A run diverged or finished. Engines are ordered by their divergence rate first (the share of
their runs that diverged), then by the mean metric over their finished runs: an engine that
diverged where another did not never ranks ahead of it on its survivors alone. Each engine's
95 % interval is the percentile interval of its replicates' mean; P(rank) the share of replicates
in which it holds its rank; each pair's difference (behind minus ahead) is the mean over the
units both finished, with its interval from the same replicates; a pair is told apart when the
interval of what orders it (the divergence rates' difference, or the metric's) excludes 0.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Mapping, NamedTuple, Sequence

import numpy as np

REPLICATES = 4000
CONFIDENCE = 0.95
BOOTSTRAP_SEED = 0
RESAMPLED = 'held-out trials, then seeds within each drawn trial; the same draw for every engine'


class HeldOutRun(NamedTuple):
    """One engine's run on one unit: its value (None: not scored) and whether it diverged."""

    trial: str
    seed: int
    value: float | None
    diverged: bool = False


@dataclass(frozen=True)
class Ranked:
    """One engine's place: rank, mean over finished runs, its interval, P(rank), divergences."""

    name: str
    rank: int
    mean: float | None
    low: float | None
    high: float | None
    p_rank: float
    n: int  # finished runs
    runs: int  # runs with a value or diverged
    diverged: int
    divergence_rate: float
    trials: int  # held-out trials it ran on


@dataclass(frozen=True)
class Difference:
    """Two engines, `ahead` ranked before `behind`: their paired difference and its interval."""

    ahead: str
    behind: str
    decided_by: str  # 'divergence' (the rates differ) or 'metric'
    mean: float | None  # behind minus ahead, over the units both finished
    low: float | None
    high: float | None
    paired: int  # units both finished
    rate_mean: float  # divergence rate, behind minus ahead
    rate_low: float
    rate_high: float
    significant: bool


@dataclass(frozen=True)
class Ranking:
    """The engines ranked, every pair's difference, and what the intervals rest on."""

    ranked: list[Ranked]
    differences: list[Difference]
    trials: int
    seeds_per_trial: int  # the fewest of any trial
    replicates: int = REPLICATES
    seed: int = BOOTSTRAP_SEED
    confidence: float = CONFIDENCE

    def difference(self, ahead: str, behind: str) -> Difference:
        """Return the difference of two engines, `ahead` ranked before `behind`."""
        return next(d for d in self.differences if (d.ahead, d.behind) == (ahead, behind))

    def bootstrap(self) -> dict[str, Any]:
        """Return what the intervals rest on: trials, seeds, replicates, seed, what is drawn."""
        return {'trials': self.trials, 'seeds_per_trial': self.seeds_per_trial,
                'replicates': self.replicates, 'seed': self.seed,
                'confidence': self.confidence, 'resampled': RESAMPLED}

    def significance(self, digits: int = 4) -> str:
        """Return one sentence: which neighbours in the ranking are told apart, which not."""
        if len(self.ranked) < 2:
            return 'one engine ranked: nothing to compare'
        apart: list[str] = []
        together: list[str] = []
        for a, b in zip(self.ranked, self.ranked[1:]):
            d = self.difference(a.name, b.name)
            if d.decided_by == 'divergence':
                said = (f'{b.name} diverged in {b.diverged}/{b.runs} runs, {a.name} in'
                        f' {a.diverged}/{a.runs}: rate {_signed(d.rate_mean, 2)}'
                        f' [{_signed(d.rate_low, 2)}, {_signed(d.rate_high, 2)}]')
            else:
                said = (f'{_signed(d.mean, digits)} [{_signed(d.low, digits)},'
                        f' {_signed(d.high, digits)}]')
            (apart if d.significant else together).append(f'{a.name} < {b.name} ({said})')
        percent = f'{self.confidence * 100:g} %'
        parts = []
        if apart:
            parts.append(f'significant (the {percent} paired interval excludes 0): '
                         + ', '.join(apart))
        if together:
            parts.append(f'not told apart (the {percent} paired interval holds 0): '
                         + ', '.join(together))
        return '; '.join(parts)


def _signed(value: float | None, digits: int) -> str:
    return '-' if value is None else f'{value:+.{digits}f}'


def _table(runs: Mapping[str, Sequence[HeldOutRun]]) -> tuple[list[str], np.ndarray, np.ndarray,
                                                              np.ndarray, np.ndarray]:
    """Return trial names, values and diverged flags (engine x trial x seed slot), seed counts."""
    trials: list[str] = []
    seeds: dict[str, list[int]] = {}
    for engine_runs in runs.values():
        for r in engine_runs:
            if r.trial not in seeds:
                trials.append(r.trial)
                seeds[r.trial] = []
            if r.seed not in seeds[r.trial]:
                seeds[r.trial].append(r.seed)
    counts = np.array([len(seeds[t]) for t in trials])
    shape = (len(runs), len(trials), int(counts.max()) if len(trials) else 0)
    values, diverged = np.full(shape, np.nan), np.zeros(shape, bool)
    for e, engine_runs in enumerate(runs.values()):
        for r in engine_runs:
            t = trials.index(r.trial)
            slot = (e, t, seeds[r.trial].index(r.seed))
            if r.diverged:
                diverged[slot] = True
            elif r.value is not None:
                values[slot] = r.value
    return trials, values, diverged, counts, np.isfinite(values) | diverged


def _draws(counts: np.ndarray, replicates: int,
           rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return drawn trials (R x T), drawn seed slots (R x T x S) and which slots count."""
    n_trials, slots = len(counts), int(counts.max())
    trials = rng.integers(0, n_trials, size=(replicates, n_trials))
    per_trial = counts[trials][..., None]  # each drawn trial draws as many seeds as it has
    seeds = np.minimum((rng.random((replicates, n_trials, slots)) * per_trial).astype(int),
                       slots - 1)
    return trials, seeds, np.arange(slots) < per_trial


def _identity(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the draw that is the data itself (every trial and seed once), as one replicate."""
    slots = int(counts.max())
    trials = np.arange(len(counts))[None, :]
    seeds = np.broadcast_to(np.arange(slots), (1, len(counts), slots))
    return trials, seeds, np.arange(slots) < counts[trials][..., None]


def _replicate_stats(values: np.ndarray, diverged: np.ndarray, present: np.ndarray,
                     draw: tuple[np.ndarray, np.ndarray, np.ndarray]) -> dict[str, np.ndarray]:
    """Return per engine and replicate: mean of finished runs, divergence rate, the runs drawn."""
    trials, seeds, valid = draw
    picked = values[:, trials[..., None], seeds]  # engine x replicate x trial x seed slot
    finished = np.isfinite(picked) & valid
    ran = present[:, trials[..., None], seeds] & valid
    lost = diverged[:, trials[..., None], seeds] & valid
    with np.errstate(invalid='ignore', divide='ignore'):
        mean = np.where(finished, picked, 0.0).sum(axis=(2, 3)) / finished.sum(axis=(2, 3))
        rate = lost.sum(axis=(2, 3)) / ran.sum(axis=(2, 3))
    return {'picked': picked, 'finished': finished, 'mean': mean, 'rate': np.nan_to_num(rate)}


def _order(stats: dict[str, np.ndarray], sign: float) -> np.ndarray:
    """Return per replicate the engines' ranks (0 best): divergence rate, then the metric."""
    metric = np.where(np.isfinite(stats['mean']), sign * stats['mean'], np.inf)
    order = np.lexsort((metric.T, stats['rate'].T), axis=-1)  # replicate x place
    return np.argsort(order, axis=-1, kind='stable')  # replicate x engine


def _interval(samples: np.ndarray, confidence: float) -> tuple[float | None, float | None]:
    finite = samples[np.isfinite(samples)]
    if not len(finite):
        return None, None
    alpha = (1.0 - confidence) / 2.0
    low, high = np.quantile(finite, [alpha, 1.0 - alpha])
    return float(low), float(high)


def _number(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def _pair_difference(stats: dict[str, np.ndarray], a: int, b: int) -> np.ndarray:
    """Return per replicate the mean of b - a over the units both finished."""
    both = stats['finished'][a] & stats['finished'][b]
    gap = np.where(both, stats['picked'][b] - stats['picked'][a], 0.0)
    with np.errstate(invalid='ignore', divide='ignore'):
        return gap.sum(axis=(1, 2)) / both.sum(axis=(1, 2))


def rank_runs(
    runs: Mapping[str, Sequence[HeldOutRun]],
    higher_is_better: bool = False,
    absolute: bool = False,
    replicates: int = REPLICATES,
    seed: int = BOOTSTRAP_SEED,
    confidence: float = CONFIDENCE,
) -> Ranking:
    """
    Return the engines ranked (see the module's doc) with their paired bootstrap statistics.

    higher_is_better ranks the highest mean first (F-score, recall); absolute ranks on the values'
    magnitudes (a signed error such as the contact onset's), whose mean is then reported. An
    engine without any run (no value, no divergence) is not ranked.
    """
    runs = {
        name: [r._replace(value=abs(r.value)) if absolute and r.value is not None else r
               for r in engine_runs]
        for name, engine_runs in runs.items()
        if any(r.diverged or (r.value is not None and np.isfinite(r.value)) for r in engine_runs)
    }
    if not runs:
        return Ranking([], [], 0, 0, replicates, seed, confidence)
    names = list(runs)
    trials, values, diverged, counts, present = _table(runs)
    sign = -1.0 if higher_is_better else 1.0
    point = _replicate_stats(values, diverged, present, _identity(counts))
    boot = _replicate_stats(values, diverged, present,
                            _draws(counts, replicates, np.random.default_rng(seed)))
    order = np.argsort(_order(point, sign)[0])  # engine indices, best first
    ranks = _order(boot, sign)
    ranked = []
    for place, e in enumerate(order):
        low, high = _interval(boot['mean'][e], confidence)
        ranked.append(Ranked(
            names[e], place + 1, _number(point['mean'][e, 0]), low, high,
            float(np.mean(ranks[:, e] == place)), int(np.isfinite(values[e]).sum()),
            int(present[e].sum()), int(diverged[e].sum()), float(point['rate'][e, 0]),
            int(present[e].any(axis=1).sum()),
        ))
    differences = []
    for i, a in enumerate(order):
        for b in order[i + 1:]:
            metric = _pair_difference(boot, a, b)
            rate = boot['rate'][b] - boot['rate'][a]
            rate_low, rate_high = _interval(rate, confidence)
            low, high = _interval(metric, confidence)
            by_rate = bool(point['rate'][b, 0] != point['rate'][a, 0])
            bounds = (rate_low, rate_high) if by_rate else (low, high)
            differences.append(Difference(
                names[a], names[b], 'divergence' if by_rate else 'metric',
                _number(_pair_difference(point, a, b)[0]), low, high,
                int((point['finished'][a] & point['finished'][b]).sum()),
                float(point['rate'][b, 0] - point['rate'][a, 0]),
                float(rate_low or 0.0), float(rate_high or 0.0),
                bounds[0] is not None and bounds[1] is not None
                and (bounds[0] > 0 or bounds[1] < 0),
            ))
    return Ranking(ranked, differences, len(trials), int(counts.min()), replicates, seed,
                   confidence)


def ranking_record(ranking: Ranking, digits: int = 4) -> dict[str, Any]:
    """Return a ranking as results files keep it: engines, differences, sentence, bootstrap."""
    return {
        'ranking': [asdict(r) for r in ranking.ranked],
        'differences': [asdict(d) for d in ranking.differences],
        'significance': ranking.significance(digits),
        'bootstrap': ranking.bootstrap(),
    }


def order_agreement(rankings: Mapping[str, Ranking]) -> str:
    """
    Return one sentence: whether the engines ranked under every key come in the same order.

    Only engines ranked under every key are compared.
    """
    keys = [k for k, r in rankings.items() if r.ranked]
    if len(keys) < 2:
        return 'only one reference ranked: nothing to compare'
    common = set.intersection(*({r.name for r in rankings[k].ranked} for k in keys))
    orders = {k: [r.name for r in rankings[k].ranked if r.name in common] for k in keys}
    first = orders[keys[0]]
    if all(orders[k] == first for k in keys[1:]):
        return f'the ranking holds across references: {" < ".join(first)}'
    return 'the ranking changes between references: ' + '; '.join(
        f'{k}: {" < ".join(orders[k])}' for k in keys
    )
