"""
The Foxglove layout shipped with the package (config/foxglove/cloth_bench_live.json).

Made with foxglove-sdk's layout types from the topic names of live/error_view.py, so the one file
opens a live run (`--live`), a comparison bag (`--record-comparison`) and a graph seen through
foxglove_bridge: a 3D view of the real cloud (grey) against each engine's scored vertices coloured
by their error (turbo colour map, 0 to 5 cm) and its cloth's triangles (red, a `--cloth-mesh`'s
or the grid's), the grippers' targets and the table; CD and HD per
engine over time; step time and latency per engine over time.
`python -m cloth_bench_ros.live.layout FILE` writes it again.
"""

from __future__ import annotations

import json
from pathlib import Path
import sys
from typing import Any

from cloth_bench_ros.live import error_view
import foxglove.layouts as fl

LAYOUT_ENGINES = ('mujoco', 'bullet', 'newton')  # an engine not in the run: its series stay empty
ERROR_RANGE_M = (0.0, 0.05)  # the colour map's span: the paper's CDs are a few centimetres


def _series(engine: str, topic: str, fields: tuple[str, ...], name: str) -> Any:
    return fl.PlotSeries(
        value=f'{error_view.topic(topic, engine)}.data[{fields.index(name)}]',
        label=f'{engine} {name}',
        timestamp_method='receiveTime',
    )


def live_layout() -> Any:
    """Return the layout (a foxglove.layouts.Layout)."""
    topics: dict[str, Any] = {
        error_view.topic(error_view.REAL_CLOUD): fl.BaseRendererPointCloudTopicSettings(
            visible=True, point_size=2, color_mode='flat', flat_color='#9e9e9eff'
        ),
        error_view.topic(error_view.TARGETS): fl.BaseRendererPosesTopicSettings(visible=True),
        error_view.topic(error_view.SCENE): fl.BaseRendererRosMarkerTopicSettings(visible=True),
    }
    for engine in LAYOUT_ENGINES:
        topics[error_view.topic(error_view.ERROR_CLOUD, engine)] = (
            fl.BaseRendererPointCloudTopicSettings(
                visible=True,
                point_size=8,
                color_mode='colormap',
                color_map='turbo',
                color_field='error',
                min_value=ERROR_RANGE_M[0],
                max_value=ERROR_RANGE_M[1],
            )
        )
        topics[error_view.topic(error_view.MESH, engine)] = (
            fl.BaseRendererRosMarkerTopicSettings(visible=True)
        )
    view = fl.ThreeDeePanel(
        title='real (grey) and simulated cloth, coloured by each vertex error (m)',
        config=fl.ThreeDeeConfig(follow_tf='world', topics=topics),
    )
    frame, step = error_view.FRAME_METRICS, error_view.STEP_METRICS
    errors = fl.PlotPanel(
        title='CD and HD per scored real frame (m)',
        config=fl.PlotConfig(
            paths=[
                _series(e, error_view.FRAME_METRICS_TOPIC, frame, name)
                for e in LAYOUT_ENGINES
                for name in ('cd', 'hd')
            ],
            show_legend=True,
        ),
    )
    timing = fl.PlotPanel(
        title='step time and latency per step (s)',
        config=fl.PlotConfig(
            paths=[
                _series(e, error_view.STEP_METRICS_TOPIC, step, name)
                for e in LAYOUT_ENGINES
                for name in ('step_time', 'latency')
            ],
            show_legend=True,
        ),
    )
    plots = fl.SplitContainer(
        direction='column',
        items=[fl.SplitItem(content=errors), fl.SplitItem(content=timing)],
    )
    return fl.Layout(
        content=fl.SplitContainer(
            direction='row',
            items=[fl.SplitItem(proportion=2, content=view), fl.SplitItem(content=plots)],
        )
    )


def layout_json() -> str:
    """Return the layout as the shipped file holds it (indented JSON, one newline at the end)."""
    return json.dumps(json.loads(live_layout().to_json()), indent=2) + '\n'


def main(argv: list[str] | None = None) -> int:
    """Write the layout to the file named (the shipped one is made so)."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print('usage: python -m cloth_bench_ros.live.layout FILE', file=sys.stderr)
        return 2
    Path(args[0]).write_text(layout_json())
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
