"""
Trial metadata: which real trial a bag holds and how its clouds are expressed.

The trial lives in `metadata.yaml` custom_data (primary, keys `cloth_bench.*`), mirrored into an
MCAP metadata record and the first message on `TRIAL_TOPIC`; see bags/README.md.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
import json
from typing import Any

from cloth_bench_ros import validation
from cloth_bench_ros.data import messages
from cloth_bench_ros.data.messages import DIAGNOSTIC_ARRAY
from cloth_bench_ros.errors import InputError
import numpy as np

CLOUD_TOPIC = '/cloth_bench/real/cloud'
TARGETS_TOPIC = '/cloth_bench/targets'
TRIAL_TOPIC = '/cloth_bench/real/trial'

CUSTOM_DATA_PREFIX = 'cloth_bench.'  # metadata.yaml custom_data keys of the trial
MCAP_TRIAL_RECORD = 'cloth_bench_trial'  # MCAP metadata record mirroring the trial
TRIAL_STATUS_NAME = 'cloth_bench/trial'  # DiagnosticStatus.name on TRIAL_TOPIC


def _identity() -> list[list[float]]:
    return np.eye(4).tolist()


@dataclass
class TrialInfo:
    """Which real trial a bag holds and how its clouds are expressed."""

    cloth: str
    trial: int
    primitive: str
    change_of_phase_frame: int | None
    source: str
    fps: float = 30.0
    units: str = 'm'
    frame_id: str = 'world'
    transform: list = field(default_factory=_identity)  # 4x4, applied to the source points

    def __post_init__(self) -> None:
        t = np.asarray(self.transform, dtype=float)
        if t.shape != (4, 4) or not np.isfinite(t).all():
            raise InputError(f'trial transform must be a finite 4x4 matrix, got shape {t.shape}')
        self.transform = t.tolist()
        self.trial = validation.integer(self.trial, 'trial', 0)
        self.fps = validation.positive(self.fps, 'trial fps', 10_000.0)
        self.change_of_phase_frame = validation.frame_index(
            self.change_of_phase_frame, 'change_of_phase_frame'
        )

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able dict."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrialInfo:
        """Inverse of `to_dict`; unknown keys are ignored, missing optional ones defaulted."""
        names = set(cls.__dataclass_fields__)
        missing = [k for k in ('cloth', 'trial', 'primitive', 'source') if k not in data]
        if missing:
            raise InputError(f'trial metadata lacks {", ".join(missing)}')
        kwargs = {k: v for k, v in data.items() if k in names}
        kwargs.setdefault('change_of_phase_frame', None)
        return cls(**kwargs)

    def to_strings(self) -> dict[str, str]:
        """Return the string key/values of custom_data, MCAP metadata and DiagnosticArray."""
        d = self.to_dict()
        out = {k: str(v) for k, v in d.items() if k not in ('transform', 'change_of_phase_frame')}
        out['fps'] = repr(self.fps)
        out['change_of_phase_frame'] = (
            '' if self.change_of_phase_frame is None else str(self.change_of_phase_frame)
        )
        out['transform'] = json.dumps(self.transform)
        return out

    @classmethod
    def from_strings(cls, data: dict[str, str]) -> TrialInfo:
        """Inverse of `to_strings`; ValueError on malformed values."""
        d: dict[str, Any] = dict(data)
        if 'trial' in d:
            d['trial'] = int(d['trial'])
        if 'fps' in d:
            d['fps'] = float(d['fps'])
        cop = d.get('change_of_phase_frame', '')
        d['change_of_phase_frame'] = int(cop) if cop not in ('', 'None', None) else None
        if 'transform' in d:
            d['transform'] = json.loads(d['transform'])
        return cls.from_dict(d)


def trial_message(trial: TrialInfo, stamp_ns: int = 0) -> Any:
    """diagnostic_msgs/DiagnosticArray carrying the trial as key/values (for TRIAL_TOPIC)."""
    kv = messages.msg_class('diagnostic_msgs/msg/KeyValue')
    status = messages.msg_class('diagnostic_msgs/msg/DiagnosticStatus')(
        level=0,
        name=TRIAL_STATUS_NAME,
        message=f'{trial.cloth} trial {trial.trial} {trial.primitive}',
        hardware_id='',
        values=[kv(key=k, value=v) for k, v in trial.to_strings().items()],
    )
    return messages.msg_class(DIAGNOSTIC_ARRAY)(
        header=messages.header(stamp_ns, trial.frame_id), status=[status]
    )


def trial_from_message(msg: Any) -> TrialInfo | None:
    """Return the trial carried by a DiagnosticArray from `trial_message`, else None."""
    for status in msg.status:
        if status.name == TRIAL_STATUS_NAME:
            return TrialInfo.from_strings({kv.key: kv.value for kv in status.values})
    return None
