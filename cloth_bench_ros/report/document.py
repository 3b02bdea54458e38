"""The report of a sweep (`cloth-bench report RESULTS`): tables, PNG plots, Markdown and HTML.

From the rows of a results.jsonl (cloth_bench_ros.studies.sweep) it renders:

- the layout of the paper's Table II: mean +- std of CD_d, HD_d, CD_q, HD_q per cloth and engine
  (over seeds and trial bags), with the paper's numbers (REFERENCE.md section 5) beside ours in
  columns marked "(paper)";
- the layout of the paper's Fig. 5: step time, L_s, CD_d and CD_q against the rate per engine,
  log scales, one figure per engine configuration of the paper sweep;
- speed against error with its Pareto front;
- per-frame CD and HD over time of the first seed, with the change of phase marked;
- timing per engine, rate and pacing: step time, latency (target sent -> state received),
  deadline misses and real-time factor; divergences; the stress suite (if given); and, for a
  settings sweep, speed against error per configuration and the cheapest configuration within a
  stated tolerance of the most accurate one.

Plots use matplotlib's Agg backend (no display). The report is report.md and report.html in the
output directory, next to the PNGs and one CSV per table.
"""

from __future__ import annotations

import csv
import html
import math
import re
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Iterable, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

ENGINE_LABEL = {"mujoco": "MuJoCo", "bullet": "Bullet", "flex": "Flex", "sofa": "SOFA", "newton": "Newton"}
ENGINE_COLOR = {"mujoco": "tab:blue", "bullet": "tab:orange", "flex": "tab:green", "sofa": "tab:red",
                "newton": "tab:purple"}
METRICS = ("CD_d", "HD_d", "CD_q", "HD_q")
PAPER_ENGINES = ("mujoco", "bullet", "flex", "sofa")
FPS = 30.0

# REFERENCE.md section 5, Table II: (mean, std, bold in the paper) per cloth, metric and engine.
PAPER_TABLE2: dict[tuple[str, str], dict[str, tuple[float, float, bool]]] = {
    ("towel", "CD_d"): {"mujoco": (0.079, 0.031, False), "bullet": (0.155, 0.093, False),
                        "flex": (0.168, 0.129, False), "sofa": (0.078, 0.029, True)},
    ("towel", "HD_d"): {"mujoco": (0.167, 0.037, True), "bullet": (0.206, 0.083, False),
                        "flex": (0.277, 0.158, False), "sofa": (0.194, 0.074, False)},
    ("towel", "CD_q"): {"mujoco": (0.079, 0.027, True), "bullet": (0.097, 0.045, False),
                        "flex": (0.080, 0.021, False), "sofa": (0.089, 0.022, False)},
    ("towel", "HD_q"): {"mujoco": (0.182, 0.040, False), "bullet": (0.243, 0.078, False),
                        "flex": (0.169, 0.024, True), "sofa": (0.174, 0.032, False)},
    ("chequered", "CD_d"): {"mujoco": (0.067, 0.026, True), "bullet": (0.119, 0.060, False),
                            "flex": (0.164, 0.134, False), "sofa": (0.068, 0.024, False)},
    ("chequered", "HD_d"): {"mujoco": (0.154, 0.035, True), "bullet": (0.242, 0.063, False),
                            "flex": (0.280, 0.180, False), "sofa": (0.178, 0.051, False)},
    ("chequered", "CD_q"): {"mujoco": (0.076, 0.025, False), "bullet": (0.094, 0.034, False),
                            "flex": (0.072, 0.019, True), "sofa": (0.102, 0.034, False)},
    ("chequered", "HD_q"): {"mujoco": (0.186, 0.055, False), "bullet": (0.243, 0.070, False),
                            "flex": (0.171, 0.024, True), "sofa": (0.198, 0.020, False)},
    ("linen", "CD_d"): {"mujoco": (0.071, 0.031, False), "bullet": (0.116, 0.054, False),
                        "flex": (0.160, 0.131, False), "sofa": (0.061, 0.024, True)},
    ("linen", "HD_d"): {"mujoco": (0.154, 0.033, False), "bullet": (0.235, 0.076, False),
                        "flex": (0.281, 0.186, False), "sofa": (0.150, 0.064, True)},
    ("linen", "CD_q"): {"mujoco": (0.083, 0.037, False), "bullet": (0.078, 0.023, False),
                        "flex": (0.075, 0.023, False), "sofa": (0.073, 0.021, True)},
    ("linen", "HD_q"): {"mujoco": (0.177, 0.068, False), "bullet": (0.182, 0.024, False),
                        "flex": (0.148, 0.045, False), "sofa": (0.137, 0.038, True)},
}
PAPER_FIG5 = (
    "Paper, Fig. 5 (towel, 10 seeds, 10 / 100 / 1000 Hz; no numbers are given in REFERENCE.md): "
    "Bullet and MuJoCo become unstable at low frequency, Flex and SOFA stay consistent; MuJoCo's "
    "error drops sharply as the frequency rises; an unstable simulator also takes much longer per "
    "step; at 100 Hz every engine needs on the order of milliseconds per step (Intel i7-10875H), "
    "which the paper judges too slow for real-time dynamic manipulation with hardware in the loop."
)


# ----------------------------------------------------------------------------- statistics


def finite(values: Iterable) -> np.ndarray:
    a = np.asarray([np.nan if v is None else v for v in values], dtype=float)
    return a[np.isfinite(a)]


@dataclass
class Stat:
    """mean +- std over the usable cells of a group, with how many there were and diverged."""

    n: int  # cells in the group
    used: int  # cells with a finite value
    diverged: int
    errors: int
    mean: float
    std: float

    def text(self, digits: int = 3, show_n: bool = True) -> str:
        if self.used == 0:
            if self.diverged:
                return f"diverged ({self.diverged}/{self.n})"
            return "error" if self.errors else "-"
        out = f"{self.mean:.{digits}f} ± {self.std:.{digits}f}"
        notes = []
        if show_n:
            notes.append(f"n={self.used}")
        if self.diverged:
            notes.append(f"{self.diverged} diverged")
        if self.errors:
            notes.append(f"{self.errors} errors")
        return out + (f" ({', '.join(notes)})" if notes else "")


def stat(rows: Sequence[dict], key: str) -> Stat:
    """Mean and (population) std of `key` over the rows that neither diverged nor failed."""
    usable = [r for r in rows if r.get("status") == "ok"]
    values = finite(r.get(key) for r in usable)
    return Stat(len(rows), len(values), sum(r.get("status") == "diverged" for r in rows),
                sum(r.get("status") == "error" for r in rows),
                float(values.mean()) if len(values) else math.nan,
                float(values.std()) if len(values) else math.nan)


def group(rows: Iterable[dict], *keys: str) -> dict[tuple, list[dict]]:
    out: dict[tuple, list[dict]] = defaultdict(list)
    for r in rows:
        out[tuple(r.get(k) for k in keys)].append(r)
    return dict(out)


def metric_name(primitive: str, kind: str) -> str:
    return f"{kind}_{'d' if primitive == 'dynamic' else 'q'}"


def pareto_front(points: Sequence[tuple[float, float]]) -> list[int]:
    """Indices of the points not dominated in (x, y), both minimised, sorted by x."""
    order = sorted((i for i, (x, y) in enumerate(points) if math.isfinite(x) and math.isfinite(y)),
                   key=lambda i: (points[i][0], points[i][1]))
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def compute_per_sim_second(row: dict) -> float:
    """Engine compute time per simulated second (s/s): mean step time x rate; < 1 is faster than real time."""
    st = row.get("step_time_mean")
    if st is None or not math.isfinite(st):
        return math.nan
    return float(st) * float(row["rate_hz"])


def engine_label(name: str) -> str:
    return ENGINE_LABEL.get(name, name)


def _fmt(value, digits: int = 3, scale: float = 1.0) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return f"{value * scale:.{digits}f}"


def _g(value, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return f"{value:.{digits}g}"


# -------------------------------------------------------------------------- report blocks


@dataclass
class Table:
    name: str  # file stem of its CSV
    headers: list[str]
    rows: list[list[str]]
    align: str = ""  # per column: l or r

    def markdown(self) -> str:
        align = self.align or "l" * len(self.headers)
        sep = ["---:" if a == "r" else "---" for a in align]
        esc = lambda s: str(s).replace("|", "/")  # noqa: E731
        lines = ["| " + " | ".join(esc(h) for h in self.headers) + " |", "| " + " | ".join(sep) + " |"]
        lines += ["| " + " | ".join(esc(c) for c in row) + " |" for row in self.rows]
        return "\n".join(lines)

    def html(self) -> str:
        align = self.align or "l" * len(self.headers)
        head = "".join(f"<th>{_inline_html(h)}</th>" for h in self.headers)
        body = "".join(
            "<tr>" + "".join(f'<td class="{"num" if a == "r" else ""}">{_inline_html(c)}</td>'
                             for c, a in zip(row, align)) + "</tr>\n" for row in self.rows)
        return f"<table>\n<thead><tr>{head}</tr></thead>\n<tbody>\n{body}</tbody>\n</table>"

    def write_csv(self, path: Path) -> None:
        with path.open("w", newline="") as f:
            w = csv.writer(f)
            w.writerow([_plain(h) for h in self.headers])
            w.writerows([[_plain(c) for c in row] for row in self.rows])


def _plain(text) -> str:
    return str(text).replace("**", "")


def _inline_html(text) -> str:
    out = html.escape(str(text))
    out = re.sub(r"\*\*(.+?)\*\*", r"<b>\1</b>", out)
    return re.sub(r"`(.+?)`", r"<code>\1</code>", out)


@dataclass
class Document:
    title: str
    blocks: list = field(default_factory=list)

    def h(self, level: int, text: str) -> None:
        self.blocks.append(("h", level, text))

    def p(self, text: str) -> None:
        self.blocks.append(("p", text))

    def table(self, table: Table) -> None:
        self.blocks.append(("table", table))

    def img(self, path: str, caption: str) -> None:
        self.blocks.append(("img", path, caption))

    def markdown(self) -> str:
        out = [f"# {self.title}", ""]
        for b in self.blocks:
            if b[0] == "h":
                out += ["#" * b[1] + " " + b[2], ""]
            elif b[0] == "p":
                out += [b[1], ""]
            elif b[0] == "table":
                out += [b[1].markdown(), ""]
            elif b[0] == "img":
                out += [f"![{b[2]}]({b[1]})", "", f"*{b[2]}*", ""]
        return "\n".join(out)

    def html(self) -> str:
        body = [f"<h1>{html.escape(self.title)}</h1>"]
        for b in self.blocks:
            if b[0] == "h":
                body.append(f"<h{b[1]}>{html.escape(b[2])}</h{b[1]}>")
            elif b[0] == "p":
                body.append(f"<p>{_inline_html(b[1])}</p>")
            elif b[0] == "table":
                body.append(b[1].html())
            elif b[0] == "img":
                body.append(f'<figure><img src="{html.escape(b[1])}" alt="{html.escape(b[2])}">'
                            f"<figcaption>{_inline_html(b[2])}</figcaption></figure>")
        style = ("body{font-family:sans-serif;max-width:1200px;margin:2em auto;padding:0 1em}"
                 "table{border-collapse:collapse;margin:1em 0;font-size:0.9em}"
                 "th,td{border:1px solid #ccc;padding:3px 6px}td.num{text-align:right}"
                 "th{background:#f0f0f0}img{max-width:100%}figcaption{font-style:italic}")
        return (f"<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>{html.escape(self.title)}</title>"
                f"<style>{style}</style></head>\n<body>\n" + "\n".join(body) + "\n</body></html>\n")


# ------------------------------------------------------------------------------ selections


def paper_rows(rows: Sequence[dict], config: str = "preset", pacing: str = "lockstep") -> list[dict]:
    return [r for r in rows if r.get("mode", "paper") == "paper" and r.get("config", "preset") == config
            and r.get("pacing", "lockstep") == pacing]


def _ordered(values: Iterable, order: Sequence = ()) -> list:
    values = set(v for v in values if v is not None)
    first = [v for v in order if v in values]
    return first + sorted(values - set(first), key=str)


def engines_of(rows: Iterable[dict]) -> list[str]:
    return _ordered((r["engine"] for r in rows), PAPER_ENGINES)


def cloths_of(rows: Iterable[dict]) -> list[str]:
    return _ordered((r["cloth"] for r in rows), ("towel", "chequered", "linen"))


def rates_of(rows: Iterable[dict]) -> list[float]:
    return sorted({float(r["rate_hz"]) for r in rows})


def table_rate(rows: Sequence[dict], wanted: float) -> float | None:
    """`wanted` if rows hold it, else the rate with the most rows."""
    rates = Counter(float(r["rate_hz"]) for r in rows)
    if not rates:
        return None
    return float(wanted) if float(wanted) in rates else rates.most_common(1)[0][0]


# -------------------------------------------------------------------------------- tables


def table2(rows: Sequence[dict], rate: float) -> Table:
    """Paper Table II layout: cloth x metric rows; ours per engine, then the paper's four engines."""
    sel = [r for r in rows if float(r["rate_hz"]) == rate]
    engines = engines_of(sel)
    headers = ["cloth", "metric"] + [f"{engine_label(e)} (ours)" for e in engines] + \
              [f"{engine_label(e)} (paper)" for e in PAPER_ENGINES]
    by = group(sel, "cloth", "primitive", "engine")
    out = []
    for cloth in cloths_of(sel):
        for metric in METRICS:
            primitive = "dynamic" if metric.endswith("_d") else "quasi_static"
            kind = metric[:2]
            stats = {e: stat(by.get((cloth, primitive, e), []), kind) for e in engines}
            if all(s.n == 0 for s in stats.values()):
                continue
            best = min((s.mean for s in stats.values() if s.used), default=math.nan)
            ours = []
            for e in engines:
                s = stats[e]
                text = s.text(3) if s.n else "-"
                ours.append(f"**{text}**" if s.used and s.mean == best and len(engines) > 1 else text)
            paper = []
            for e in PAPER_ENGINES:
                v = PAPER_TABLE2.get((cloth, metric), {}).get(e)
                paper.append("-" if v is None else (f"**{v[0]:.3f} ± {v[1]:.3f}**" if v[2] else f"{v[0]:.3f} ± {v[1]:.3f}"))
            out.append([cloth, metric] + ours + paper)
    return Table("table2", headers, out, "ll" + "r" * (len(headers) - 2))


def fig5_table(rows: Sequence[dict], cloth: str, name: str = "fig5") -> Table:
    """The numbers behind Fig. 5: per engine and rate, step time, L_s, CD_d, CD_q, divergences."""
    sel = [r for r in rows if r["cloth"] == cloth]
    headers = ["engine", "rate Hz", "substeps", "step mean ms", "step p99 ms", "L_s (m)", "CD_d (m)", "CD_q (m)",
               "diverged"]
    by = group(sel, "engine", "rate_hz")
    out = []
    for e in engines_of(sel):
        for rate in rates_of(sel):
            g = by.get((e, rate), [])
            if not g:
                continue
            ok = [r for r in g if r.get("status") == "ok"]
            st = finite(r.get("step_time_mean") for r in ok) * 1e3
            p99 = finite(r.get("step_time_p99") for r in ok) * 1e3
            subs = {r.get("substeps") for r in g if r.get("substeps")}
            dyn = stat([r for r in g if r["primitive"] == "dynamic"], "CD")
            qs = stat([r for r in g if r["primitive"] == "quasi_static"], "CD")
            ls = stat(g, "L_s")
            out.append([engine_label(e), f"{rate:g}", ",".join(str(s) for s in sorted(subs)) or "-",
                        _fmt(st.mean() if len(st) else math.nan, 3), _fmt(p99.mean() if len(p99) else math.nan, 3),
                        _g(ls.mean), dyn.text(4, False) if dyn.n else "-", qs.text(4, False) if qs.n else "-",
                        f"{sum(r.get('status') == 'diverged' for r in g)}/{len(g)}"])
    return Table(name, headers, out, "lrrrrrrrr")


def timing_table(rows: Sequence[dict]) -> Table:
    """Per engine, rate and pacing: step time, latency, deadline misses, real-time factor."""
    headers = ["engine", "rate Hz", "pacing", "config", "runs", "step p50 ms", "step p99 ms", "step max ms",
               "latency p50 ms", "latency p99 ms", "latency max ms", "deadline misses", "real-time factor"]
    by = group(rows, "engine", "rate_hz", "pacing", "config")
    out = []
    for key in sorted(by, key=lambda k: (engines_of(rows).index(k[0]), k[1], k[2], str(k[3]))):
        g = [r for r in by[key] if r.get("status") in ("ok", "diverged")]
        if not g:
            continue
        ok = [r for r in g if r.get("status") == "ok"] or g

        def med(k, scale=1e3):
            v = finite(r.get(k) for r in ok)
            return _fmt(float(np.median(v)) if len(v) else math.nan, 3, scale)

        misses = [(r.get("deadline_misses"), r.get("latency_count")) for r in ok if r.get("latency_count")]
        miss_txt = "-"
        if misses:
            m = sum(x or 0 for x, _ in misses)
            n = sum(c for _, c in misses)
            miss_txt = f"{m / len(misses):.0f} / {n / len(misses):.0f} ({100 * m / n:.1f} %)"
        rtf = finite(r.get("real_time_factor") for r in ok)
        out.append([engine_label(key[0]), f"{key[1]:g}", key[2], key[3], str(len(g)), med("step_time_p50"),
                    med("step_time_p99"), med("step_time_max"), med("latency_p50"), med("latency_p99"),
                    med("latency_max"), miss_txt, _fmt(float(np.median(rtf)) if len(rtf) else math.nan, 2, 1.0)])
    return Table("timing", headers, out, "lrllrrrrrrrrr")


def stability_table(rows: Sequence[dict]) -> Table:
    headers = ["engine", "rate Hz", "config", "task", "cells", "diverged", "errors", "median diverged at step",
               "most common reason", "L_s (m)"]
    by = group(rows, "engine", "rate_hz", "config", "primitive")
    out = []
    for key in sorted(by, key=lambda k: (engines_of(rows).index(k[0]), k[1], str(k[2]), k[3])):
        g = by[key]
        div = [r for r in g if r.get("status") == "diverged"]
        steps = [r["diverged_at_step"] for r in div if r.get("diverged_at_step") is not None]
        reasons = Counter(re.sub(r"[\d.]+", "#", r.get("diverged_reason") or "") for r in div)
        out.append([engine_label(key[0]), f"{key[1]:g}", key[2], key[3], str(len(g)), str(len(div)),
                    str(sum(r.get("status") == "error" for r in g)),
                    f"{int(np.median(steps))}" if steps else "-",
                    reasons.most_common(1)[0][0] if reasons else "-", _g(stat(g, "L_s").mean)])
    return Table("stability", headers, out, "lrllrrrrlr")


def errors_table(rows: Sequence[dict]) -> Table:
    errs = [r for r in rows if r.get("status") == "error"]
    out = [[r["engine"], f"{r['rate_hz']:g}", r["cloth"], r["primitive"], str(r["seed"]), r.get("config", ""),
            (r.get("error") or "")[:200]] for r in errs]
    return Table("errors", ["engine", "rate Hz", "cloth", "task", "seed", "config", "error"], out)


# ------------------------------------------------------------------------------- settings


@dataclass
class ConfigResult:
    engine: str
    cloth: str
    primitive: str
    rate: float
    config: str
    cd: Stat
    hd: Stat
    step_ms: float
    cost: float  # compute per simulated second
    stable: bool


def settings_results(rows: Sequence[dict]) -> list[ConfigResult]:
    sel = [r for r in rows if r.get("mode") == "settings"]
    out = []
    for (e, cloth, prim, rate, config), g in group(sel, "engine", "cloth", "primitive", "rate_hz", "config").items():
        ok = [r for r in g if r.get("status") == "ok"]
        st = finite(r.get("step_time_mean") for r in ok)
        cost = finite(compute_per_sim_second(r) for r in ok)
        out.append(ConfigResult(e, cloth, prim, float(rate), config, stat(g, "CD"), stat(g, "HD"),
                                float(st.mean() * 1e3) if len(st) else math.nan,
                                float(cost.mean()) if len(cost) else math.nan,
                                len(ok) == len(g) and len(g) > 0))
    return out


def recommend(results: Sequence[ConfigResult], tol_rel: float, tol_abs: float
              ) -> tuple[ConfigResult | None, ConfigResult | None, float]:
    """(most accurate, cheapest within tolerance, tolerance in m) among stable configurations.

    Within tolerance: mean CD <= best CD + max(tol_rel * best CD, tol_abs).
    """
    stable = [r for r in results if r.stable and math.isfinite(r.cd.mean)]
    if not stable:
        return None, None, math.nan
    best = min(stable, key=lambda r: (r.cd.mean, r.step_ms))
    tol = max(tol_rel * best.cd.mean, tol_abs)
    within = [r for r in stable if r.cd.mean <= best.cd.mean + tol]
    cheapest = min(within, key=lambda r: (r.step_ms, r.cd.mean))
    return best, cheapest, tol


def settings_tables(rows: Sequence[dict], tol_rel: float, tol_abs: float) -> tuple[list[Table], list[str], list[dict]]:
    """Per engine, cloth, task and rate: every configuration, and the recommendation sentences."""
    results = settings_results(rows)
    tables, notes, recs = [], [], []
    by = defaultdict(list)
    for r in results:
        by[(r.engine, r.cloth, r.primitive, r.rate)].append(r)
    for key in sorted(by, key=lambda k: (engines_of(rows).index(k[0]), k[1], k[2], k[3])):
        group_results = by[key]
        best, cheap, tol = recommend(group_results, tol_rel, tol_abs)
        front = pareto_front([(r.step_ms, r.cd.mean) if r.stable else (math.nan, math.nan) for r in group_results])
        rows_out = []
        for i, r in sorted(enumerate(group_results), key=lambda x: (x[1].step_ms if math.isfinite(x[1].step_ms)
                                                                     else math.inf)):
            flags = []
            if best is not None and r is best:
                flags.append("most accurate")
            if cheap is not None and r is cheap:
                flags.append("**recommended**")
            if i in front:
                flags.append("Pareto")
            if not r.stable:
                flags.append("unstable")
            within = best is not None and r.stable and math.isfinite(r.cd.mean) and r.cd.mean <= best.cd.mean + tol
            rows_out.append([r.config, _fmt(r.step_ms, 3), _g(r.cost), r.cd.text(4, False), r.hd.text(4, False),
                             "yes" if within else "no", ", ".join(flags)])
        e, cloth, prim, rate = key
        name = f"settings_{e}_{cloth}_{prim}_{rate:g}hz"
        tables.append(Table(name, ["configuration", "step mean ms", "compute s/s", metric_name(prim, "CD") + " (m)",
                                   metric_name(prim, "HD") + " (m)", "within tolerance", "notes"],
                            rows_out, "lrrrrll"))
        if best is None:
            notes.append(f"{engine_label(e)}, {cloth} {prim} at {rate:g} Hz: no stable configuration.")
            continue
        notes.append(
            f"{engine_label(e)}, {cloth} {prim} at {rate:g} Hz: the most accurate configuration is `{best.config}` "
            f"({metric_name(prim, 'CD')} = {best.cd.mean:.4f} m, {best.step_ms:.3f} ms per step); the cheapest "
            f"within tolerance (CD <= best + max({tol_rel:.0%} of best, {tol_abs * 1e3:g} mm) = "
            f"{best.cd.mean + tol:.4f} m) is **`{cheap.config}`** (CD = {cheap.cd.mean:.4f} m, "
            f"{cheap.step_ms:.3f} ms per step, {best.step_ms / cheap.step_ms:.1f}x faster than the most accurate).")
        recs.append({"engine": e, "cloth": cloth, "primitive": prim, "rate_hz": rate, "best": best.config,
                     "best_cd": best.cd.mean, "best_step_ms": best.step_ms, "recommended": cheap.config,
                     "recommended_cd": cheap.cd.mean, "recommended_step_ms": cheap.step_ms, "tolerance_m": tol})
    # One configuration for every task and cloth of an engine: within tolerance everywhere, cheapest in total.
    for e in engines_of([r for r in rows if r.get("mode") == "settings"]):
        keys = [k for k in by if k[0] == e]
        if len(keys) < 2:
            continue
        ok_everywhere = None
        cost = defaultdict(float)
        for k in keys:
            best, _, tol = recommend(by[k], tol_rel, tol_abs)
            within = {r.config for r in by[k] if best is not None and r.stable and r.cd.mean <= best.cd.mean + tol}
            ok_everywhere = within if ok_everywhere is None else ok_everywhere & within
            for r in by[k]:
                cost[r.config] += r.step_ms if math.isfinite(r.step_ms) else math.inf
        if ok_everywhere:
            choice = min(ok_everywhere, key=lambda c: cost[c])
            notes.append(f"{engine_label(e)}, one configuration for all {len(keys)} task/cloth/rate groups: "
                         f"**`{choice}`** is within tolerance in each, at {cost[choice]:.3f} ms summed step time.")
        else:
            notes.append(f"{engine_label(e)}: no single configuration is within tolerance in every group.")
    return tables, notes, recs


# ---------------------------------------------------------------------------------- plots


def _plain_log(ax, axis: str = "xy") -> None:
    """Log-axis tick labels as plain numbers (0.2, 10, 1000) rather than 2 x 10^-1."""
    from matplotlib.ticker import FuncFormatter

    fmt = FuncFormatter(lambda v, _: f"{v:g}")
    for name in axis:
        a = ax.xaxis if name == "x" else ax.yaxis
        if a.get_scale() != "log":
            continue
        low, high = sorted(ax.get_xlim() if name == "x" else ax.get_ylim())
        a.set_major_formatter(fmt)
        # Less than about a decade shown: label the minor ticks too, or the axis has no numbers.
        few = low > 0 and high / low < 20
        a.set_minor_formatter(FuncFormatter(lambda v, _: f"{v:.3g}") if few else FuncFormatter(lambda v, _: ""))


def _savefig(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_fig5(rows: Sequence[dict], cloth: str, path: Path, title: str) -> Path:
    """Step time, L_s, CD_d and CD_q against rate per engine (log-log), mean +- std over seeds.
    Rates at which some runs diverged are marked with an open marker and their count."""
    sel = [r for r in rows if r["cloth"] == cloth]
    fig, axes = plt.subplots(2, 2, figsize=(10, 7.5))
    panels = [("step_time_mean", None, 1e3, "step time (ms)"), ("L_s", None, 1.0, "L_s (m)"),
              ("CD", "dynamic", 1.0, "CD_d (m)"), ("CD", "quasi_static", 1.0, "CD_q (m)")]
    for ax, (key, prim, scale, label) in zip(axes.ravel(), panels):
        for e in engines_of(sel):
            xs, ys, es, div = [], [], [], []
            for rate in rates_of(sel):
                g = [r for r in sel if r["engine"] == e and float(r["rate_hz"]) == rate
                     and (prim is None or r["primitive"] == prim)]
                if not g:
                    continue
                s = stat(g, key)
                if s.used:
                    xs.append(rate)
                    ys.append(s.mean * scale)
                    es.append(s.std * scale)
                    if s.diverged:
                        div.append((rate, s.mean * scale, f"{s.diverged}/{s.n} div."))
                elif s.diverged:
                    div.append((rate, None, f"all {s.n} div."))
            color = ENGINE_COLOR.get(e)
            if xs:
                ax.errorbar(xs, ys, yerr=es, marker="o", capsize=3, color=color, label=engine_label(e))
            for rate, y, text in div:
                if y is None:
                    ax.annotate(f"{engine_label(e)}: {text}", (rate, 0.02), xycoords=("data", "axes fraction"),
                                color=color, fontsize=8, rotation=90, va="bottom")
                else:
                    ax.plot([rate], [y], marker="o", mfc="white", ms=11, color=color)
                    ax.annotate(text, (rate, y), textcoords="offset points", xytext=(6, 6), color=color, fontsize=8)
        ax.set_xscale("log")
        if ax.has_data():
            ax.set_yscale("log")
        _plain_log(ax)
        from matplotlib.ticker import FixedLocator, NullFormatter

        ax.xaxis.set_major_locator(FixedLocator(rates_of(sel)))
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("simulator rate (Hz)")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    fig.suptitle(title, fontsize=11)
    return _savefig(fig, path)


def plot_speed_error(rows: Sequence[dict], path: Path, title: str, label_key: str = "rate") -> tuple[Path, list]:
    """CD against compute per simulated second, one point per engine x rate (x config), with the
    Pareto front (minimal compute and CD) per task. Returns the path and the front points."""
    fig, axes = plt.subplots(1, 2, figsize=(12, 5))
    fronts = []
    for ax, prim in zip(axes, ("dynamic", "quasi_static")):
        sel = [r for r in rows if r["primitive"] == prim]
        pts, labels, colors = [], [], []
        for (e, rate, config), g in sorted(group(sel, "engine", "rate_hz", "config").items(), key=lambda x: str(x[0])):
            cd = stat(g, "CD")
            cost = finite(compute_per_sim_second(r) for r in g if r.get("status") == "ok")
            if not cd.used or not len(cost):
                continue
            pts.append((float(cost.mean()), cd.mean))
            text = f"{rate:g} Hz" if label_key == "rate" else config
            if label_key == "rate" and config != "preset":
                text += f" {config}"
            labels.append((e, text, cd.std))
            colors.append(ENGINE_COLOR.get(e, "gray"))
        for (x, y), (e, text, sd), c in zip(pts, labels, colors):
            ax.errorbar([x], [y], yerr=[sd], marker="o", color=c, capsize=2, ms=5)
            ax.annotate(text, (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7, color=c)
        front = pareto_front(pts)
        if front:
            fx = [pts[i][0] for i in front]
            fy = [pts[i][1] for i in front]
            ax.step(fx, fy, where="post", color="black", lw=1.2, ls="--", label="Pareto front")
            ax.scatter(fx, fy, s=120, facecolors="none", edgecolors="black", zorder=3)
            fronts += [{"task": prim, "engine": labels[i][0], "point": labels[i][1], "compute_s_per_s": pts[i][0],
                        "CD": pts[i][1]} for i in front]
        for e in engines_of(sel):
            ax.plot([], [], marker="o", color=ENGINE_COLOR.get(e, "gray"), ls="", label=engine_label(e))
        ax.axvline(1.0, color="gray", lw=0.8, ls=":")
        ax.set_xscale("log")
        _plain_log(ax)
        ax.set_xlabel("engine compute per simulated second (s/s); left of 1 = faster than real time")
        ax.set_ylabel(f"{metric_name(prim, 'CD')} (m)")
        ax.set_title(prim)
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
        else:
            ax.text(0.5, 0.5, "no runs of this task", transform=ax.transAxes, ha="center", color="gray")
    fig.suptitle(title, fontsize=11)
    return _savefig(fig, path), fronts


_SHORT = {"grid": "", "self_collision": "sc:", "timestep": "dt:", "solver_iterations": "it:", "substeps": "sub:"}


def short_config(label: str) -> str:
    """"grid=11x15,self_collision=off,timestep=0.005" -> "11x15 sc:off dt:0.005"."""
    parts = []
    for item in label.split(","):
        name, _, value = item.partition("=")
        parts.append(f"{_SHORT.get(name, name + ':')}{value}" if value else item)
    return " ".join(parts)


def plot_settings(rows: Sequence[dict], path: Path, title: str, recommended: Sequence[str] = ()) -> Path:
    """One engine's settings sweep: CD against compute per configuration and task. Colour: mesh;
    marker: internal time step; open marker: self-collision on; the Pareto front dashed and
    labelled; the recommended configuration starred."""
    from matplotlib.lines import Line2D

    prims = [p for p in ("dynamic", "quasi_static") if any(r["primitive"] == p for r in rows)]
    fig, axes = plt.subplots(1, len(prims), figsize=(7.5 * len(prims), 5.5), squeeze=False)
    grids = sorted({r.get("grid") or "default" for r in rows},
                   key=lambda g: (math.prod(int(v) for v in g.split("x")) if "x" in g else 0))
    steps = sorted({str(r.get("params", {}).get("timestep", "preset")) for r in rows})
    cmap = plt.get_cmap("viridis", max(2, len(grids)))
    markers = ["o", "s", "^", "D", "v", "P", "X"]
    for ax, prim in zip(axes[0], prims):
        pts, labels = [], []
        for config, g in sorted(group([r for r in rows if r["primitive"] == prim], "config").items(), key=str):
            cd = stat(g, "CD")
            cost = finite(compute_per_sim_second(r) for r in g if r.get("status") == "ok")
            if not cd.used or not len(cost) or cd.used < cd.n:
                continue  # unstable configurations are in the table, not on the plot
            r0 = g[0]
            color = cmap(grids.index(r0.get("grid") or "default"))
            marker = markers[steps.index(str(r0.get("params", {}).get("timestep", "preset"))) % len(markers)]
            hollow = bool(r0.get("params", {}).get("self_collision"))
            x, y = float(cost.mean()), cd.mean
            ax.errorbar([x], [y], yerr=[cd.std], color=color, marker=marker, ms=7, capsize=2, ls="",
                        mfc="white" if hollow else color)
            if config[0] in recommended:
                ax.scatter([x], [y], marker="*", s=260, facecolors="none", edgecolors="red", zorder=4)
            pts.append((x, y))
            labels.append(config[0])
        front = pareto_front(pts)
        if front:
            ax.step([pts[i][0] for i in front], [pts[i][1] for i in front], where="post", color="black", lw=1,
                    ls="--")
            for n, i in enumerate(front):
                ax.annotate(short_config(labels[i]), pts[i], textcoords="offset points",
                            xytext=(6, 8 if n % 2 == 0 else -12), fontsize=7)
        ax.set_xscale("log")
        _plain_log(ax)
        ax.set_xlabel("engine compute per simulated second (s/s)")
        ax.set_ylabel(f"{metric_name(prim, 'CD')} (m)")
        ax.set_title(prim)
        ax.grid(True, which="both", alpha=0.3)
        handles = [Line2D([], [], color=cmap(i), marker="o", ls="", label=f"mesh {g}") for i, g in enumerate(grids)]
        handles += [Line2D([], [], color="gray", marker=markers[i % len(markers)], ls="", label=f"dt {t}")
                    for i, t in enumerate(steps)]
        handles += [Line2D([], [], color="gray", marker="o", mfc="white", ls="", label="self-collision on"),
                    Line2D([], [], color="black", ls="--", label="Pareto front"),
                    Line2D([], [], color="red", marker="*", mfc="none", ls="", ms=12, label="recommended")]
        ax.legend(handles=handles, fontsize=7, loc="best")
    fig.suptitle(title, fontsize=11)
    return _savefig(fig, path)


def _read_frames(path: Path) -> dict[str, np.ndarray]:
    with path.open() as f:
        rows = list(csv.DictReader(f))
    return {k: np.array([float(r[k]) if r[k] not in ("", "nan") else np.nan for r in rows])
            for k in ("t", "cd", "hd")}


def plot_frames(rows: Sequence[dict], results_dir: Path, cloth: str, path: Path) -> Path | None:
    """Per-frame CD and HD over time for each task, engine and rate (first seed and trial),
    with the change of phase of the dynamic trial marked."""
    sel = [r for r in rows if r["cloth"] == cloth and r.get("frames_csv")]
    prims = [p for p in ("dynamic", "quasi_static") if any(r["primitive"] == p for r in sel)]
    if not prims:
        return None
    fig, axes = plt.subplots(len(prims), 2, figsize=(12, 3.8 * len(prims)), squeeze=False)
    styles = ["-", "--", ":", "-."]
    for row_axes, prim in zip(axes, prims):
        g = [r for r in sel if r["primitive"] == prim]
        first = {}
        for r in sorted(g, key=lambda r: (r.get("trial", 0), r["seed"])):
            first.setdefault((r["engine"], float(r["rate_hz"])), r)
        rates = sorted({k[1] for k in first})
        cut = next((r.get("change_of_phase_frame") for r in g if r.get("change_of_phase_frame") is not None), None)
        for ax, kind in zip(row_axes, ("cd", "hd")):
            for (e, rate), r in sorted(first.items(), key=lambda x: (engines_of(g).index(x[0][0]), x[0][1])):
                f = results_dir / r["frames_csv"]
                if not f.is_file():
                    continue
                data = _read_frames(f)
                ax.plot(data["t"], data[kind], color=ENGINE_COLOR.get(e), ls=styles[rates.index(rate) % 4], lw=1.2,
                        label=f"{engine_label(e)} {rate:g} Hz" + (" (diverged)" if r.get("diverged") else ""))
            if prim == "dynamic" and cut is not None:
                ax.axvline(cut / FPS, color="red", lw=1, ls="--")
                ax.annotate(f"change of phase (frame {cut}) ", (cut / FPS, 0.03), xycoords=("data", "axes fraction"),
                            color="red", fontsize=8, ha="right", va="bottom", rotation=90)
            ax.set_xlabel("time since the start of the quintic part (s)")
            ax.set_ylabel(f"{kind.upper()} (m)")
            ax.set_title(f"{cloth} {prim}: per-frame {kind.upper()} (seed {min(r['seed'] for r in first.values())})")
            ax.grid(True, alpha=0.3)
            if ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize=7)
    return _savefig(fig, path)


def plot_latency(rows: Sequence[dict], path: Path) -> Path | None:
    """Latency p50 / p99 / max per engine and rate (realtime-paced runs if any, else all)."""
    rt = [r for r in rows if r.get("pacing") == "realtime" and r.get("status") in ("ok", "diverged")]
    sel = rt or [r for r in rows if r.get("status") == "ok"]
    groups = group([r for r in sel if r.get("latency_p50") is not None], "engine", "rate_hz", "pacing")
    if not groups:
        return None
    fig, ax = plt.subplots(figsize=(max(6, 1.3 * len(groups) + 2), 4.5))
    keys = sorted(groups, key=lambda k: (k[2], engines_of(sel).index(k[0]), k[1]))
    x = np.arange(len(keys))
    for i, (q, marker) in enumerate((("latency_p50", "o"), ("latency_p99", "s"), ("latency_max", "^"))):
        vals = [np.median(finite(r.get(q) for r in groups[k])) * 1e3 if len(finite(r.get(q) for r in groups[k]))
                else np.nan for k in keys]
        ax.scatter(x + (i - 1) * 0.15, vals, marker=marker, label=q.split("_")[1], zorder=3)
    for j, k in enumerate(keys):
        ax.plot([j - 0.35, j + 0.35], [1e3 / k[1]] * 2, color="red", lw=1.5)
    ax.plot([], [], color="red", label="deadline = 1 / rate")
    ax.set_xticks(x, [f"{engine_label(k[0])}\n{k[1]:g} Hz\n{k[2]}" for k in keys], fontsize=8)
    ax.set_yscale("log")
    _plain_log(ax)
    ax.set_ylabel("latency, target due -> state received (ms)")
    ax.grid(True, which="both", axis="y", alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("per-step latency against the deadline")
    return _savefig(fig, path)


# --------------------------------------------------------------------------------- report


@dataclass
class ReportOutcome:
    markdown: Path
    html: Path
    images: list[Path]
    tables: dict[str, Table]
    recommendations: list[dict]
    pareto: list[dict]


def write_results_csv(rows: Sequence[dict], path: Path) -> None:
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v}" if not isinstance(v, dict) else ";".join(f"{a}={b}" for a, b in v.items()))
                        for k, v in r.items()})


def render_report(rows: Sequence[dict], results_dir: Path, out_dir: Path, stress_rows: Sequence[dict] | None = None,
                  wanted_rate: float = 100.0, fig5_cloth: str = "towel", tol_rel: float = 0.05,
                  tol_abs: float = 0.002, title: str = "cloth_bench_ros: speed against error") -> ReportOutcome:
    """Render every table and plot of the rows into out_dir (report.md, report.html, *.png, *.csv)."""
    from cloth_bench_ros.studies.stress import stress_table, verdict

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    results_dir = Path(results_dir)
    doc = Document(title)
    images: list[Path] = []
    tables: dict[str, Table] = {}
    pareto: list[dict] = []

    def add_table(t: Table) -> None:
        tables[t.name] = t
        t.write_csv(out_dir / f"{t.name}.csv")
        doc.table(t)

    def add_img(p: Path | None, caption: str) -> None:
        if p is not None:
            images.append(p)
            doc.img(p.name, caption)

    write_results_csv(rows, out_dir / "results.csv")
    status = Counter(r.get("status") for r in rows)
    versions = sorted({f"{engine_label(r['engine'])} {r['engine_version']}" for r in rows if r.get("engine_version")})
    compute = sum(r.get("cell_wall_s") or 0 for r in rows if isinstance(r.get("cell_wall_s"), (int, float))
                  and math.isfinite(r.get("cell_wall_s")))
    loads = finite(r.get("load_avg_1min") for r in rows)
    load_text = (f" Step times are wall times: the 1-minute load average at the end of the cells was "
                 f"{np.median(loads):.1f} (median; {loads.min():.1f}-{loads.max():.1f}) on "
                 f"{rows[0].get('cpu_count') or '?'} cores; a load above the core count inflates them."
                 if len(loads) else "")
    doc.p(f"Rendered {datetime.now(timezone.utc).strftime('%Y-%m-%d %H:%M UTC')} from {len(rows)} cells "
          f"({status.get('ok', 0)} ok, {status.get('diverged', 0)} diverged, {status.get('error', 0)} errors); "
          f"engines {', '.join(versions) or '-'}; {compute / 3600:.2f} h of cell compute in total. "
          f"CD and HD are one-sided L1 distances in metres (REFERENCE.md section 3); mean ± std over seeds and trial "
          f"bags (population std); a diverged run is counted, not averaged. All results here are ours unless a "
          f"column or paragraph is marked **paper**." + load_text)

    config_counts = Counter(r.get("config", "preset") for r in rows if r.get("mode", "paper") == "paper"
                            and r.get("pacing", "lockstep") == "lockstep")
    # The Table II configuration: the presets if the sweep has them, else its most common configuration.
    main_config = "preset" if "preset" in config_counts else (config_counts.most_common(1)[0][0]
                                                              if config_counts else "preset")
    paper = paper_rows(rows, main_config)
    paper_configs = [main_config] + sorted(c for c in config_counts if c != main_config) if config_counts else []
    if paper:
        rate = table_rate(paper, wanted_rate)
        doc.h(2, f"Table II layout: accuracy per cloth and engine at {rate:g} Hz")
        what = "engine presets" if main_config == "preset" else f"configuration `{main_config}`"
        doc.p(f"Columns marked (ours): this system, {what}, lockstep pacing, {rate:g} Hz, over "
              f"{len({(r['seed'], r.get('trial', 0)) for r in paper if float(r['rate_hz']) == rate})} seed x trial "
              f"combinations per cell; bold = best of ours. Columns marked (paper) are the paper's Table II "
              f"(REFERENCE.md section 5: real rags, 3 trials x 20 seeds, MuJoCo 3.1.1, Bullet 3.26, Flex 1.2, "
              f"SOFA 23.06; bold = best in the paper). The paper scores real clouds; ours are scored against the "
              f"bags given to the sweep, so the columns compare layouts and magnitudes, not the same data.")
        add_table(table2(paper, rate))

    for config in paper_configs:
        sel = paper_rows(rows, config)
        if not sel:
            continue
        cloths = cloths_of(sel)
        cloth = fig5_cloth if fig5_cloth in cloths else cloths[0]
        suffix = "" if config == main_config else "_" + re.sub(r"[^A-Za-z0-9]+", "_", config).strip("_")
        doc.h(2, f"Fig. 5 layout: frequency study, {cloth}" + ("" if config == "preset" else f", {config}"))
        what = ("engine presets (internal time step from the preset; the rate is the target rate)"
                if config == "preset" else f"configuration `{config}`"
                + (" (one internal step per target, as in the paper's frequency study)" if "step=1/rate" in config else ""))
        doc.p(f"Ours: {what}; mean ± std over seeds, log scales; open markers: some runs diverged.")
        add_img(plot_fig5(sel, cloth, out_dir / f"fig5{suffix}.png",
                          f"{cloth}: step time, L_s, CD_d, CD_q against rate ({config})"),
                f"Fig. 5 layout, {cloth}, {config} (ours)")
        add_table(fig5_table(sel, cloth, f"fig5{suffix}"))
        doc.p("**paper** — " + PAPER_FIG5)

    lockstep = [r for r in rows if r.get("mode", "paper") == "paper" and r.get("pacing", "lockstep") == "lockstep"]
    speed_cloth = fig5_cloth if any(r["cloth"] == fig5_cloth for r in lockstep) else (cloths_of(lockstep) or [None])[0]
    speed_sel = [r for r in lockstep if r["cloth"] == speed_cloth]  # one cloth: every configuration has it
    if speed_sel:
        doc.h(2, f"Speed against error ({speed_cloth})")
        doc.p("One point per engine, rate and configuration (mean over seeds); x: engine compute per simulated "
              "second (mean step time x rate; below 1 the engine alone is faster than real time); y: CD of the "
              "task. The Pareto front joins the points that no other point beats in both.")
        p, front = plot_speed_error(speed_sel, out_dir / "speed_error.png",
                                    f"{speed_cloth}: CD against compute per simulated second; Pareto front dashed")
        pareto += front
        add_img(p, "speed against error with its Pareto front (ours)")
        add_table(Table("pareto", ["task", "engine", "point", "compute s/s", "CD (m)"],
                        [[f["task"], engine_label(f["engine"]), f["point"], _g(f["compute_s_per_s"]),
                          _fmt(f["CD"], 4)] for f in front], "lllrr"))

    if paper:
        doc.h(2, "Per-frame CD and HD over time")
        any_frames = False
        for cloth in cloths_of(paper):
            p = plot_frames(paper, results_dir, cloth, out_dir / f"frames_{cloth}.png")
            if p is not None:
                any_frames = True
                add_img(p, f"{cloth}: per-frame CD and HD, first seed; red: change of phase (ours)")
        if not any_frames:
            doc.p("No per-frame scores were kept in this sweep (frames are kept for the first seed by default).")

    timed = [r for r in rows if r.get("status") in ("ok", "diverged")]
    if timed:
        doc.h(2, "Timing and hardware in the loop")
        doc.p("Step time: wall time of one engine step (all internal substeps) per target. Latency: wall time "
              "until the engine's state reaches the evaluator, counted from the target's due time on the "
              "wall-clock schedule (first target + k / rate) with realtime pacing, so a run that falls behind "
              "its schedule shows it, and from the target's arrival with lockstep pacing. "
              "Deadline misses: steps whose latency exceeds 1 / rate (mean per run / steps per run). Real-time "
              "factor: simulated time over wall time of the run (lockstep runs as fast as they can; realtime "
              "runs are paced by the wall clock and cannot exceed 1). Medians over runs.")
        add_table(timing_table(timed))
        add_img(plot_latency(timed, out_dir / "latency.png"), "latency percentiles against the deadline (ours)")

    if rows:
        doc.h(2, "Stability")
        add_table(stability_table(rows))
        errs = errors_table(rows)
        if errs.rows:
            doc.h(3, "Cells that failed")
            add_table(errs)

    recs: list[dict] = []
    if any(r.get("mode") == "settings" for r in rows):
        doc.h(2, "Model only what the scene needs: settings against error")
        doc.p(f"Factorial sweep over the settings that cost time. Tolerance: a configuration is within tolerance "
              f"when its mean CD is at most the best stable configuration's plus max({tol_rel:.0%} of it, "
              f"{tol_abs * 1e3:g} mm); the recommendation is the cheapest (mean step time) within tolerance. "
              f"A configuration with any diverged seed is unstable and never recommended. Table contact cannot be "
              f"switched off: neither engine exposes it.")
        settings = [r for r in rows if r.get("mode") == "settings"]
        s_tables, notes, recs = settings_tables(rows, tol_rel, tol_abs)
        for e in engines_of(settings):
            chosen = [x["recommended"] for x in recs if x["engine"] == e]
            p = plot_settings([r for r in settings if r["engine"] == e], out_dir / f"settings_{e}.png",
                              f"{engine_label(e)}: configurations, CD against compute (stable ones)", chosen)
            add_img(p, f"{engine_label(e)}: speed against error per configuration, Pareto front dashed, "
                       f"recommended starred (ours)")
        doc.p("Within one configuration, settings that do not change the result (equal CD) can still differ in "
              "measured step time by run-to-run timing noise of the machine; compare step times that differ by "
              "less than about 20 % with care.")
        doc.h(3, "Recommendations")
        for n in notes:
            doc.p(n)
        for t in s_tables:
            doc.h(3, t.name.replace("settings_", "").replace("_", " "))
            add_table(t)

    if stress_rows:
        doc.h(2, "Stress suite: hard cases")
        v = verdict(stress_rows)
        doc.p("; ".join(f"{engine_label(e)}: {len(c)} of {sum(r['engine'] == e for r in stress_rows)} cases diverged"
                        f" ({', '.join(c) or 'none'})" for e, c in v.items()) + ".")
        t = Table("stress", [], [])
        md = stress_table(stress_rows).splitlines()
        t.headers = [h.strip() for h in md[0].strip("|").split("|")]
        t.rows = [[c.strip() for c in line.strip("|").split("|")] for line in md[2:]]
        t.align = "llrlrrrrrrl"
        add_table(t)

    from cloth_bench_ros.report.cross_reference import cross_reference_section  # late: it imports this module

    xref = cross_reference_section(rows)
    if xref is not None:
        doc.h(2, xref[0])
        doc.p(xref[1])
        add_table(xref[2])

    md_path, html_path = out_dir / "report.md", out_dir / "report.html"
    md_path.write_text(doc.markdown())
    html_path.write_text(doc.html())
    return ReportOutcome(md_path, html_path, images, tables, recs, pareto)
