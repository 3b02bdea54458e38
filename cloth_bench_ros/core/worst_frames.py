"""
The worst frame of each engine, kept beside a run's summary.json for the report to draw.

The report renders and runs nothing, so the run keeps, per engine, the arrays of its scored frame
of the largest CD (in the scoring window, if any frame of it was scored): the real points, the
scored vertices (at the real frame's stamp) and each vertex's error (its L1 distance to the
nearest real point, the term CD averages). One .npz file,
read without pickles; engine names in it are labels only, never paths.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any, NamedTuple

from cloth_bench_ros.errors import ClothBenchError
from cloth_bench_ros.safe_io import atomic_write_bytes
import numpy as np

WORST_FRAMES_FILE = 'worst_frames.npz'
MAX_FILE_BYTES = 256 * 1024 * 1024


class WorstFrameError(ClothBenchError, ValueError):
    """A worst_frames.npz that cannot be read (not an npz, arrays missing or misshapen)."""


class WorstFrame(NamedTuple):
    engine: str
    frame: int
    t: float
    cd: float
    hd: float
    real: np.ndarray  # (m, 3)
    vertices: np.ndarray  # (n, 3)
    errors: np.ndarray  # (n,)


def write_worst_frames(out_dir: Path, worst: dict[str, Any]) -> Path | None:
    """Write each engine's worst ScoredFrame (core.evaluation) to out_dir; None if none scored."""
    if not worst:
        return None
    arrays: dict[str, Any] = {'engines': np.array(sorted(worst), dtype=str)}
    for i, engine in enumerate(sorted(worst)):
        s = worst[engine]
        arrays[f'{i}_score'] = np.array([s.score.frame, s.score.t, s.score.cd, s.score.hd])
        arrays[f'{i}_real'] = np.asarray(s.real, dtype=np.float32)
        arrays[f'{i}_vertices'] = np.asarray(s.vertices, dtype=np.float64)
        arrays[f'{i}_errors'] = np.asarray(s.errors, dtype=np.float64)
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    path = Path(out_dir) / WORST_FRAMES_FILE
    atomic_write_bytes(path, buffer.getvalue())
    return path


def read_worst_frames(path: Path) -> list[WorstFrame]:
    """Return the worst frames of a run's worst_frames.npz, one per engine (checked shapes)."""
    path = Path(path)
    if path.stat().st_size > MAX_FILE_BYTES:
        raise WorstFrameError(f'{path}: larger than {MAX_FILE_BYTES} bytes')
    try:
        with np.load(path, allow_pickle=False) as data:
            engines = [str(e) for e in data['engines']]
            out = []
            for i, engine in enumerate(engines):
                score = np.asarray(data[f'{i}_score'], dtype=float)
                real = np.asarray(data[f'{i}_real'], dtype=float)
                vertices = np.asarray(data[f'{i}_vertices'], dtype=float)
                errors = np.asarray(data[f'{i}_errors'], dtype=float)
                if (
                    score.shape != (4,)
                    or real.ndim != 2
                    or real.shape[1:] != (3,)
                    or vertices.ndim != 2
                    or vertices.shape[1:] != (3,)
                    or errors.shape != (len(vertices),)
                ):
                    raise WorstFrameError(f'{path}: arrays of {engine!r} have the wrong shape')
                out.append(
                    WorstFrame(
                        engine,
                        int(score[0]),
                        float(score[1]),
                        float(score[2]),
                        float(score[3]),
                        real,
                        vertices,
                        errors,
                    )
                )
            return out
    except WorstFrameError:
        raise
    except (OSError, ValueError, KeyError) as exc:
        raise WorstFrameError(f'{path}: not a worst-frames file ({exc})') from None
