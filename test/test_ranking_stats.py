"""The ranking's statistics on values whose right answer is known (rank.ranking)."""

from __future__ import annotations

import itertools
import json

from cloth_bench_ros.rank.ranking import (
    HeldOutRun,
    rank_runs,
    ranking_record,
)
import numpy as np
import pytest

TRIALS = ('t1', 't2', 't3')
SEEDS = (1, 2)


def runs_of(values: np.ndarray, diverged: np.ndarray | None = None) -> list[HeldOutRun]:
    """Return trial x seed values as runs (a diverged run has no value)."""
    lost = np.zeros(values.shape, bool) if diverged is None else diverged
    return [
        HeldOutRun(TRIALS[t], SEEDS[s], None if lost[t, s] else float(values[t, s]),
                   bool(lost[t, s]))
        for t in range(values.shape[0]) for s in range(values.shape[1])
    ]


def exact_percentiles(values: np.ndarray, low: float, high: float) -> tuple[float, float, float]:
    """
    Return the two-level bootstrap distribution's percentiles of the mean, by enumeration.

    Every draw of the trials with replacement, then of each drawn trial's seeds with replacement,
    is equally likely. Also return how far the distribution's steps are from `low` and `high` (a
    sampled bootstrap lands on the exact percentile when that margin is many standard errors).
    """
    n_trials, n_seeds = values.shape
    means = np.round(np.sort([
        np.mean([values[t, s] for t, chosen in zip(trials, np.reshape(seeds, (n_trials, n_seeds)))
                 for s in chosen])
        for trials in itertools.product(range(n_trials), repeat=n_trials)
        for seeds in itertools.product(range(n_seeds), repeat=n_trials * n_seeds)
    ]), 12)  # one step of the distribution, however the sum was rounded
    support = np.unique(means)
    cdf = np.searchsorted(means, support, side='right') / len(means)
    found, margin = [], 1.0
    for p in (low, high):
        i = int(np.argmax(cdf >= p))
        found.append(support[i])
        margin = min(margin, cdf[i] - p, p - (cdf[i - 1] if i else 0.0))
    return found[0], found[1], margin


def test_a_constant_paired_difference_is_told_apart_where_each_engines_interval_is_wide():
    """
    Two engines whose runs differ by 2 mm on every trial and seed, over trials 25 mm apart.

    Their own intervals are wide and overlap (the trials differ), but every resample of the
    trials moves both alike: the paired difference's interval has no width, and the pair is
    significant. The overlap rule of intervals resampled per engine said "not told apart".
    """
    a = np.array([[0.020, 0.0203], [0.030, 0.0302], [0.045, 0.0449]])
    ranking = rank_runs({'b': runs_of(a + 0.002), 'a': runs_of(a)})
    first, second = ranking.ranked
    assert (first.name, second.name) == ('a', 'b')
    assert first.high - first.low > 0.01 and second.high - second.low > 0.01
    assert first.high > second.low  # the engines' own intervals overlap
    d = ranking.difference('a', 'b')
    assert d.decided_by == 'metric' and d.paired == 6 and d.significant
    assert d.low == pytest.approx(0.002, abs=1e-12) and d.high == pytest.approx(0.002, abs=1e-12)
    assert first.p_rank == second.p_rank == 1.0
    assert ranking.significance() == (
        'significant (the 95 % paired interval excludes 0): a < b (+0.0020 [+0.0020, +0.0020])'
    )


def test_the_paired_interval_is_the_exact_two_level_bootstraps():
    """Three trials x two seeds: the sampled interval is the one every draw enumerated gives."""
    a = np.array([[0.030, 0.031], [0.041, 0.040], [0.027, 0.029]])
    gap = np.array([[4.0, 4.0], [6.0, 5.0], [1.0, 7.0]]) * 1e-3  # b - a per trial and seed
    low, high, margin = exact_percentiles(gap, 0.025, 0.975)
    assert (low, high) == pytest.approx((0.003, 0.006))
    replicates = 100_000
    assert margin > 10 * np.sqrt(0.025 * 0.975 / replicates)  # far from a sampling coin toss
    ranking = rank_runs({'a': runs_of(a), 'b': runs_of(a + gap)}, replicates=replicates)
    d = ranking.difference('a', 'b')
    assert (d.low, d.high) == pytest.approx((low, high))
    assert d.mean == pytest.approx(gap.mean()) and d.significant
    own_low, own_high, _ = exact_percentiles(a, 0.025, 0.975)
    assert ranking.ranked[0].low <= own_low + 1e-3 and ranking.ranked[0].high >= own_high - 1e-3
    assert ranking.bootstrap() == {
        'trials': 3, 'seeds_per_trial': 2, 'replicates': replicates, 'seed': 0,
        'confidence': 0.95, 'resampled': ranking.bootstrap()['resampled'],
    }


def test_a_diverged_run_counts_and_never_ranks_an_engine_on_its_survivors_alone():
    steady = np.full((3, 2), 0.040)
    fragile = np.full((3, 2), 0.020)  # better on the runs it finishes
    lost_once = np.zeros((3, 2), bool)
    lost_once[0, 1] = True  # diverged on trial t1, seed 2
    runs = {
        'fragile': runs_of(fragile, lost_once),
        'steady': runs_of(steady),
        'lost': runs_of(steady, np.ones((3, 2), bool)),
    }
    ranking = rank_runs(runs)
    assert [r.name for r in ranking.ranked] == ['steady', 'fragile', 'lost']
    steady_r, fragile_r, lost_r = ranking.ranked
    assert (fragile_r.mean, fragile_r.n, fragile_r.runs, fragile_r.diverged) == (0.020, 5, 6, 1)
    assert fragile_r.divergence_rate == pytest.approx(1 / 6) and steady_r.divergence_rate == 0
    assert (lost_r.mean, lost_r.low, lost_r.divergence_rate) == (None, None, 1.0)
    # A replicate that draws the diverged run ranks fragile second, one that misses it first:
    # the trial is drawn k ~ Bin(3, 1/3) times, and each time misses seed 2 with (1/2)^2.
    misses = (2 / 3 + 1 / 3 * 1 / 4) ** 3
    assert fragile_r.p_rank == pytest.approx(1 - misses, abs=0.03)
    assert steady_r.p_rank == fragile_r.p_rank and lost_r.p_rank == 1.0
    d = ranking.difference('steady', 'fragile')
    assert d.decided_by == 'divergence' and d.rate_mean == pytest.approx(1 / 6)
    assert d.mean == pytest.approx(-0.020) and d.paired == 5
    assert not d.significant  # 42 % of the replicates never draw the diverged run
    sentence = ranking.significance()
    assert 'steady < fragile (fragile diverged in 1/6 runs, steady in 0/6: rate +0.17' in sentence
    assert 'not told apart (the 95 % paired interval holds 0): steady < fragile' in sentence
    assert 'significant (the 95 % paired interval excludes 0): fragile < lost' in sentence
    # Diverged on one seed of every trial: told apart (a replicate draws no seed 2 in 1/64).
    always = rank_runs({'fragile': runs_of(fragile, np.ones((3, 2), bool) & [False, True]),
                        'steady': runs_of(steady)})
    assert [r.name for r in always.ranked] == ['steady', 'fragile']
    assert always.difference('steady', 'fragile').significant
    record = json.loads(json.dumps(ranking_record(ranking), allow_nan=False))
    assert set(record) == {'ranking', 'differences', 'significance', 'bootstrap'}
    assert {'name', 'rank', 'mean', 'low', 'high', 'p_rank', 'n', 'runs', 'diverged',
            'divergence_rate', 'trials'} <= set(record['ranking'][0])
    assert len(record['differences']) == 3  # every pair


def test_one_trial_draws_its_seeds_and_more_is_better_ranks_the_highest_first():
    """The cross-reference case: one reference bag, five seeds; an F-score ranks highest first."""
    seeds = {'a': [0.70, 0.72, 0.69, 0.71, 0.70], 'b': [0.60, 0.65, 0.62, 0.61, 0.66]}
    runs = {n: [HeldOutRun('ref', s, v) for s, v in enumerate(vs, 1)] for n, vs in seeds.items()}
    ranking = rank_runs(runs, higher_is_better=True)
    assert [r.name for r in ranking.ranked] == ['a', 'b']
    assert ranking.bootstrap()['trials'] == 1 and ranking.bootstrap()['seeds_per_trial'] == 5
    a = ranking.ranked[0]
    assert min(seeds['a']) <= a.low < a.mean < a.high <= max(seeds['a'])
    d = ranking.difference('a', 'b')
    assert d.high < 0 and d.significant  # b - a: lower F-score
