"""The report's sections of the metrics beside the paper's, Fig. 4's numbers, rankings."""

import math

from cloth_bench_ros.core.evaluation import FrameScore
from cloth_bench_ros.core.run_files import write_run_report
from cloth_bench_ros.rank.ranking import HeldOutRun, rank_runs
from cloth_bench_ros.report.metric_sections import fig4_table, metrics_table, PAPER_FIG4
from cloth_bench_ros.report.run_report import result_table


def _row(engine: str, seed: int, cd: float, fscore: float, onset: float | None) -> dict:
    return {
        'status': 'ok', 'engine': engine, 'config': 'preset', 'rate_hz': 100.0, 'cloth': 'towel',
        'primitive': 'dynamic', 'seed': seed, 'CD': cd, 'HD': 3 * cd, 'CD_reverse': cd / 2,
        'F': fscore, 'EMD': 0.1, 'contact_onset_error_s': onset,
    }


ROWS = [
    _row('mujoco', 0, 0.03, 0.30, -0.2), _row('mujoco', 1, 0.03, 0.32, -0.2),
    _row('bullet', 0, 0.05, 0.50, 0.05), _row('bullet', 1, 0.05, 0.52, 0.05),
]


def _ranked_engines(table) -> list[str]:
    return [line[3].split()[0] for line in table.rows]


def test_the_metrics_table_ranks_on_the_chosen_metric():
    assert _ranked_engines(metrics_table(ROWS)) == ['MuJoCo', 'Bullet']  # the paper's CD
    assert _ranked_engines(metrics_table(ROWS, 'fscore')) == ['Bullet', 'MuJoCo']  # more is better
    assert _ranked_engines(metrics_table(ROWS, 'contact_onset')) == ['Bullet', 'MuJoCo']  # |error|
    table = metrics_table(ROWS)
    assert table.headers[2] == 'rank (cd)' and 'emd' in table.headers
    paper_only = [{k: v for k, v in r.items() if k in ('CD', 'status')} for r in ROWS]
    assert metrics_table(paper_only) is None


def test_the_ranking_orders_by_direction():
    def ranked(samples: dict[str, list[float]], **how: bool) -> list[str]:
        runs = {n: [HeldOutRun(f't{i}', 1, v) for i, v in enumerate(vs)]
                for n, vs in samples.items()}
        return [r.name for r in rank_runs(runs, **how).ranked]

    samples = {'a': [0.3, 0.31], 'b': [0.5, 0.52]}
    assert ranked(samples) == ['a', 'b']
    assert ranked(samples, higher_is_better=True) == ['b', 'a']
    signed = {'late': [0.2, 0.2], 'early': [-0.1, -0.1]}
    assert ranked(signed, absolute=True) == ['early', 'late']


def test_fig4_table_puts_ours_beside_the_papers_values(tmp_path):
    scores = [
        FrameScore(engine, k, k / 30, 0.01 + 0.002 * k, 0.05, True, False)
        for engine in ('mujoco', 'newton')
        for k in range(120)
    ]
    summary = {'run': {'primitive': 'dynamic'}, 'engines': {}}
    write_run_report(tmp_path, summary, scores)
    table = fig4_table(tmp_path)
    mujoco, newton = table.rows
    assert table.headers[1] == 't = 0.5 s CD / HD'
    paper = PAPER_FIG4['mujoco']['dynamic'][0]
    assert mujoco[1] == f'0.040 / 0.050 (paper {paper[0]:.3f} / {paper[1]:.3f})'  # frame 15
    assert mujoco[4] == '0.220 / 0.050 (paper 0.136 / 0.220)'  # t = 3.5 s: frame 105
    assert 'paper' not in newton[1]  # the paper has no Newton


def test_the_run_table_shows_the_metrics_beside_the_papers():
    timing = {'mean': 1e-3, 'p50': 1e-3, 'p99': 2e-3, 'max': 3e-3}
    engine = {
        'CD_d': 0.03, 'HD_d': 0.1, 'L_s': 1e-4, 'step_time': timing, 'diverged': False,
        'CD_reverse_d': 0.0123, 'F_d': 0.5, 'contact_onset_error_s': None,
        'surface_metrics': {
            'fscore_threshold_m': 0.01, 'ot_samples': 80, 'reverse_samples': 1000,
        },
    }
    text = result_table({'run': {'primitive': 'dynamic'}, 'engines': {'mujoco': engine}})
    line = next(x for x in text.splitlines() if x.startswith('mujoco') and '0.0123' in x)
    assert '0.500' in line and line.rstrip().endswith('-')  # no onset: shown as -
    assert 'P/R/F at 1 cm; EMD on 80 + 80 points spread over each' in text
    assert 'CD rev and R on 1000 real points spread over the frame, HD rev on all' in text
    plain = {k: v for k, v in engine.items() if not k.startswith(('CD_r', 'F', 'contact'))}
    assert 'CD rev' not in result_table({'run': {'primitive': 'dynamic'}, 'engines': {'e': plain}})
    assert math.isfinite(engine['CD_d'])
