"""
Online scoring of simulated states against real frames (the evaluator node's core, no ROS).

Real frames and simulated states arrive in any interleaving, each in time order. A real frame at
time t is scored against the simulated state of the same time: the state stamped t when there is
one, otherwise the linear interpolation of the two states that bracket t (at 100 Hz and 30 fps
only every third real frame falls on a simulator step).

Given the mesh's faces, every scored frame also gets the surface metrics (core/surface_metrics.py)
and, for the dynamic task, the contact-onset error: the same rule (core/phase.py `in_contact`)
applied to the real points and to as many points drawn on the simulated surface uniformly by area
(`surface_samples`, at most 2000: `contact_samples`) at every scored real frame. Without faces
(identification trials) only the paper's CD/HD are computed.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
import math
from typing import Callable

from cloth_bench_ros.core.metrics import latency_stats, RealCloud, StabilityAccumulator
from cloth_bench_ros.core.phase import (
    CONTACT_FLOOR,
    CONTACT_MARGIN,
    CONTACT_MIN_FRACTION,
    CONTACT_MIN_POINTS,
    CONTACT_SAMPLES,
    contact_samples,
    first_contact,
    in_contact,
)
from cloth_bench_ros.core.scene import TABLE_TOP_Z
from cloth_bench_ros.core.surface_metrics import (
    NAN_SCORES,
    settings as surface_settings,
    SURFACE_FIELDS,
    surface_samples,
    surface_scores,
)
from cloth_bench_ros.core.trajectory import as_task, SUFFIX_TASK, TaskLike
from cloth_bench_ros.metric_choice import METRICS
import numpy as np

IRREGULAR_TOLERANCE = 0.25  # an interval off 1/fps by more than this fraction is reported


@dataclass(frozen=True)
class FrameScore:
    engine: str
    frame: int  # real frame index from the start of the quintic part
    t: float  # s from the start of the quintic part
    cd: float
    hd: float
    in_window: bool  # counts toward CD_d/HD_d (dynamic: before the change of phase) or CD_q/HD_q
    diverged: bool
    # the surface metrics (NaN when not computed: no faces given, or a diverged state)
    cd_reverse: float = math.nan
    hd_reverse: float = math.nan
    cd_surface: float = math.nan
    hd_surface: float = math.nan
    cd_two_sided: float = math.nan
    hd_two_sided: float = math.nan
    precision: float = math.nan
    recall: float = math.nan
    fscore: float = math.nan
    emd: float = math.nan
    real_contact: bool | None = None  # dynamic task: the real cloth touches the table
    sim_contact: bool | None = None  # ... and the simulated one, by the same rule


@dataclass(frozen=True)
class ScoredFrame:
    """
    One scored (real frame, engine) pair with the arrays behind its numbers.

    `errors` holds each vertex's own term of CD: its L1 distance to the nearest real point (CD is
    their mean, HD their maximum); None when the engine had diverged.
    """

    score: FrameScore
    stamp_ns: int  # the real frame's stamp
    real: np.ndarray  # (m, 3) the real points scored against
    vertices: np.ndarray  # (n, 3) the engine's vertices at the real frame's stamp (interpolated)
    errors: np.ndarray | None  # (n,) L1 distance of each vertex to the nearest real point


def _worse(a: FrameScore, b: FrameScore) -> bool:
    """Return True if a is a worse frame than b: in the scoring window first, then larger CD."""
    return (a.in_window, a.cd) > (b.in_window, b.cd)


@dataclass
class _EngineState:
    states: deque = field(default_factory=lambda: deque(maxlen=4096))  # (stamp_ns, vertices)
    last_stamp: int = -1
    last_step_stamp: int = -1
    stability: StabilityAccumulator = field(default_factory=StabilityAccumulator)
    step_times: list = field(default_factory=list)
    latencies: list = field(default_factory=list)  # s, target sent -> state received (wall clock)
    diverged_step: int | None = None
    diverged_time: float | None = None
    diverged_reason: str = ''
    skipped_targets: int = 0  # targets the simulator never stepped (a newer one was waiting)
    contact: list = field(default_factory=list)  # (t, touching) at every scored real frame
    mesh_mismatch: int = 0  # vertices of a state that does not fit the faces (0: none)


class OnlineEvaluator:
    """Pairs real frames with simulated states by stamp and scores them as they complete."""

    def __init__(
        self,
        engines: list[str],
        task: TaskLike,
        quintic_start_ns: int,
        change_of_phase_frame: int | None,
        fps: float = 30.0,
        keep_pairs: bool = False,
        faces: np.ndarray | None = None,
    ) -> None:
        # the task's window: before the first table contact (its frames' CD_d) or every frame
        self.suffix = as_task(task).suffix
        self.quintic_start_ns = int(quintic_start_ns)
        self.change_of_phase_frame = change_of_phase_frame
        self.fps = fps
        self.engines = {name: _EngineState() for name in engines}
        self._pending: deque[tuple[int, RealCloud]] = deque()
        self.scores: list[FrameScore] = []
        self.real_frames = 0
        self.empty_frames = 0
        self.nan_points_dropped = 0
        self.unpaired_frames = 0  # (engine, frame) pairs without a state
        self.scored_frames = 0  # real frames scored by at least one engine
        self.unpaired_real_frames = 0  # real frames no engine had a state for
        self.irregular_intervals = 0  # real frames not about 1/fps after the previous one
        self._last_real_ns: int | None = None
        self.keep_pairs = (
            keep_pairs  # keep (score, real points, vertices) for the comparison outputs
        )
        self.pairs: list[tuple[FrameScore, np.ndarray, np.ndarray, np.ndarray | None]] = []
        # Each scored frame goes to these callables as it is scored (the live view, ROS topics).
        self.listeners: list[Callable[[ScoredFrame], None]] = []
        self.worst: dict[str, ScoredFrame] = {}  # per engine: its largest CD (see _worse)
        # the mesh's triangles: the surface metrics and contact onset are computed with them
        self.faces = None if faces is None else np.asarray(faces, dtype=np.int64)
        self.mesh_vertices = 0 if self.faces is None else int(self.faces.max()) + 1
        self.contact_rule = self.faces is not None and self.suffix == 'd'
        self.real_contact: list[tuple[float, bool]] = []

    # inputs
    def add_state(self, engine: str, stamp_ns: int, vertices: np.ndarray) -> None:
        """Take a simulated state; states before the quintic part only advance the stamp."""
        e = self.engines[engine]
        if (
            stamp_ns <= e.last_stamp
        ):  # the same state again (a resent target answered): counted once
            return
        e.last_stamp = stamp_ns
        if stamp_ns < self.quintic_start_ns:
            return
        e.states.append((stamp_ns, vertices))
        if e.diverged_step is None and np.isfinite(vertices).all():
            e.stability.add(vertices)
        if self._pending and self._pending[0][0] <= stamp_ns:  # else no frame is ready yet
            self._score_ready()

    def add_step(
        self,
        engine: str,
        stamp_ns: int,
        step: int,
        step_time: float,
        diverged: bool,
        reason: str = '',
        skipped_targets: int = 0,
    ) -> None:
        """Take the simulator's report of one step: compute time, divergence, skipped targets."""
        e = self.engines[engine]
        e.last_step_stamp = stamp_ns
        e.skipped_targets = max(e.skipped_targets, int(skipped_targets))
        if step > 0:
            e.step_times.append(step_time)
        if diverged and e.diverged_step is None:
            e.diverged_step = step
            e.diverged_time = (stamp_ns - self.quintic_start_ns) / 1e9
            e.diverged_reason = reason

    def add_latency(self, engine: str, latency_s: float) -> None:
        """Record the wall time from a target's sending to the engine's state arriving."""
        self.engines[engine].latencies.append(latency_s)

    def add_real(self, stamp_ns: int, points: np.ndarray, nan_dropped: int = 0) -> None:
        """Take a real frame (stamp in run time); an empty cloud is counted and skipped."""
        self.real_frames += 1
        self.nan_points_dropped += nan_dropped
        if self._last_real_ns is not None:
            interval = (stamp_ns - self._last_real_ns) / 1e9
            if abs(interval * self.fps - 1.0) > IRREGULAR_TOLERANCE:
                self.irregular_intervals += 1
        self._last_real_ns = stamp_ns
        if len(points) == 0:
            self.empty_frames += 1
            return
        self._pending.append((stamp_ns, RealCloud.of(points)))
        self._score_ready()

    # scoring
    def _state_at(self, e: _EngineState, t_ns: int) -> np.ndarray | None:
        if e.last_stamp < t_ns:
            return None
        states = e.states
        for i in range(len(states) - 1, -1, -1):
            s, v = states[i]
            if s == t_ns:
                return v
            if s < t_ns:
                s1, v1 = states[i + 1]
                w = (t_ns - s) / (s1 - s)
                return (1.0 - w) * v + w * v1
        return None  # older than the buffer: cannot happen while frames are scored in order

    def _score_ready(self) -> None:
        while self._pending:
            stamp, cloud = self._pending[0]
            if any(e.last_stamp < stamp for e in self.engines.values()):
                return
            self._pending.popleft()
            self._score(stamp, cloud)

    def _score(self, stamp: int, cloud: RealCloud) -> None:
        t = (stamp - self.quintic_start_ns) / 1e9
        frame = int(round(t * self.fps))
        if self.suffix == 'd' and self.change_of_phase_frame is not None:
            in_window = frame < self.change_of_phase_frame
        else:
            in_window = True
        paired = False
        real_touch = in_contact(cloud.points) if self.contact_rule else None
        for name, e in self.engines.items():
            vertices = self._state_at(e, stamp)
            if vertices is None:
                self.unpaired_frames += 1
                continue
            paired = True
            diverged = e.diverged_time is not None and t >= e.diverged_time - 1e-9
            surface, sim_touch = NAN_SCORES, None
            errors = None
            if diverged or not np.isfinite(vertices).all():
                cd = hd = math.nan
                diverged = True
            else:  # the per-vertex terms, then CD and HD of them (RealCloud.chamfer_hausdorff)
                errors = cloud.nearest_l1(vertices)
                cd, hd = float(errors.mean()), float(errors.max())
                if self.faces is not None and len(vertices) != self.mesh_vertices:
                    e.mesh_mismatch = len(vertices)  # another grid than the faces': not scored
                elif self.faces is not None:
                    surface = surface_scores(cloud, vertices, self.faces)
                    if self.contact_rule:
                        drawn = contact_samples(len(cloud.points))
                        sim_touch = in_contact(surface_samples(vertices, self.faces, drawn))
            if real_touch is not None:
                e.contact.append((t, bool(sim_touch)))
            self.scores.append(
                FrameScore(
                    name, frame, t, cd, hd, in_window, diverged, **surface.as_dict(),
                    real_contact=real_touch, sim_contact=sim_touch,
                )
            )
            scored = ScoredFrame(self.scores[-1], stamp, cloud.points, vertices, errors)
            if self.keep_pairs:
                self.pairs.append((self.scores[-1], cloud.points, np.array(vertices), errors))
            if errors is not None and (
                name not in self.worst or _worse(scored.score, self.worst[name].score)
            ):
                self.worst[name] = scored
            for listener in self.listeners:
                listener(scored)
        if paired:
            self.scored_frames += 1
            if real_touch is not None:
                self.real_contact.append((t, real_touch))
        else:
            self.unpaired_real_frames += 1

    def complete(self, final_stamp_ns: int) -> bool:
        """Return True once every engine has reported its state and step at the final stamp."""
        return all(
            min(e.last_stamp, e.last_step_stamp) >= final_stamp_ns for e in self.engines.values()
        )

    def finish(self) -> None:
        """Frames still waiting for a state never get one: count them as unpaired."""
        self.unpaired_frames += len(self._pending) * len(self.engines)
        self.unpaired_real_frames += len(self._pending)
        self._pending.clear()

    # results
    def summary(
        self,
        period_s: float | None = None,
        wall_s: float | None = None,
        sim_s: float | None = None,
    ) -> dict[str, dict]:
        """Return per engine: CD/HD over the window, L_s, step time, latency, divergence."""
        out = {}
        suffix = self.suffix
        for name, e in self.engines.items():
            rows = [s for s in self.scores if s.engine == name]
            window = [s for s in rows if s.in_window]
            diverged_in_window = any(s.diverged for s in window)
            cd = [s.cd for s in window]
            hd = [s.hd for s in window]
            out[name] = {
                f'CD_{suffix}': math.nan if diverged_in_window or not cd else float(np.mean(cd)),
                f'HD_{suffix}': math.nan if diverged_in_window or not hd else float(np.mean(hd)),
                'L_s': e.stability.value,
                'step_time': latency_stats(np.asarray(e.step_times)).as_dict(),
                'latency': latency_stats(np.asarray(e.latencies)).as_dict(),
                'deadline_misses': (
                    int(np.sum(np.asarray(e.latencies) > period_s)) if period_s else None
                ),
                'real_time_factor': sim_s / wall_s if sim_s and wall_s else None,
                'skipped_targets': e.skipped_targets,
                'frames_scored': len(rows),
                'frames_in_window': len(window),
                'diverged': e.diverged_step is not None,
                'diverged_at_step': e.diverged_step,
                'diverged_at_time': e.diverged_time,
                'diverged_reason': e.diverged_reason,
            }
            if self.faces is not None:
                for f in SURFACE_FIELDS:
                    values = [getattr(s, f) for s in window]
                    out[name][METRICS[f].summary_key(SUFFIX_TASK[suffix])] = (
                        math.nan if diverged_in_window or not values else float(np.mean(values))
                    )
                settings: dict[str, object] = dict(surface_settings())
                out[name]['surface_metrics'] = settings
                if e.mesh_mismatch:
                    settings['not_computed'] = (
                        f'the states have {e.mesh_mismatch} vertices, the faces given'
                        f' {self.mesh_vertices}: the surface metrics need the simulators grid'
                        ' (evaluator parameters grid_nx, grid_nz)'
                    )
            if self.contact_rule:
                onset = contact_onset(self.real_contact, e.contact)
                if e.mesh_mismatch:
                    onset.update(sim_s=None, error_s=None, reason='not computed: another grid')
                out[name]['contact_onset'] = onset
                out[name]['contact_onset_error_s'] = onset['error_s']
        return out

    def real_summary(self) -> dict[str, int]:
        return {
            'frames': self.real_frames,
            'empty_frames_skipped': self.empty_frames,
            'nan_points_dropped': self.nan_points_dropped,
            'unpaired_frames': self.unpaired_frames,
            'scored_frames': self.scored_frames,
            'unpaired_real_frames': self.unpaired_real_frames,
            'irregular_intervals': self.irregular_intervals,
        }


CONTACT_RULE = (
    f'in contact: at least max({CONTACT_MIN_POINTS}, {CONTACT_MIN_FRACTION * 100:g} %) of the'
    f' points {CONTACT_FLOOR * 100:g}-{CONTACT_MARGIN * 100:g} cm above the table top'
    f' (z {TABLE_TOP_Z:g} m; the cleaning removes the lowest {CONTACT_FLOOR * 100:g} cm with the'
    " table); real: the frame's points; simulated: as many points drawn on its surface"
    f' uniformly by area, at most {CONTACT_SAMPLES} (the same share on both sides); checked at'
    ' every scored real frame (30 fps); a sequence in contact from its first frame gives no onset'
)


def contact_onset(real: list[tuple[float, bool]], sim: list[tuple[float, bool]]) -> dict:
    """
    Return the contact onsets (s) of the real and simulated cloth and the error sim - real.

    Each is the first frame in contact by `core.phase.first_contact`; when either has none the
    error is None and `reason` says which.
    """
    found = {}
    for side, flags in (('real', real), ('sim', sim)):
        search = first_contact(touching for _, touching in flags)
        found[side] = (flags[search.index][0] if search.index is not None else None, search)
    real_s, sim_s = found['real'][0], found['sim'][0]
    reasons = [
        f'{side}: {search.reason}'
        for side, (at, search) in found.items()
        if at is None
    ]
    return {
        'real_s': real_s,
        'sim_s': sim_s,
        'error_s': sim_s - real_s if real_s is not None and sim_s is not None else None,
        'reason': '; '.join(reasons) if reasons else 'both touch',
        'rule': CONTACT_RULE,
    }


FRAME_FATES = (
    'scored',
    'before_start',
    'other_trials',
    'after_trajectory',
    'empty',
    'unpaired',
    'skipped_by_start_offset',
    'not_received',
)


def frame_accounting(replay: dict, real: dict) -> dict:
    """
    Return what became of every frame on the bag's topic.

    The recorder's sorting plus the evaluator's.

    replay: the recorder's counts (frames_in_bag, before_start, after_trajectory,
    empty_after_cleaning, to_send, ...); real: `OnlineEvaluator.real_summary()`. The fates add up
    to frames_in_bag unless frames went missing in transport, which `not_received` then counts.
    """
    sent = replay.get('to_send', real['frames']) - replay.get('skipped_by_start_offset', 0)
    fates = {
        'scored': real['scored_frames'],
        'before_start': replay.get('before_start', 0),
        'other_trials': replay.get('other_trials', 0),  # other repetitions in the recording
        'after_trajectory': replay.get('after_trajectory', 0),
        'empty': replay.get('empty_after_cleaning', 0) + real['empty_frames_skipped'],
        'unpaired': real['unpaired_real_frames'],
        'skipped_by_start_offset': replay.get('skipped_by_start_offset', 0),
        'not_received': max(0, sent - real['frames']),
    }
    total = replay.get('frames_in_bag', real['frames'])
    return {'frames_in_bag': total, **fates, 'adds_up': sum(fates.values()) == total}


def accounting_line(acc: dict) -> str:
    """One line: the bag's count and what became of each frame, e.g. for the CLI."""
    parts = [f'{acc[k]} {k.replace("_", " ")}' for k in FRAME_FATES if acc.get(k) or k == 'scored']
    check = 'adds up' if acc['adds_up'] else 'DOES NOT add up'
    return f'real frames: {acc["frames_in_bag"]} on the topic = {" + ".join(parts)} ({check})'
