"""
The live view: a run's clouds, targets and errors as topics, streamed or written to a bag.

Modules: `error_view` (the error topics' names and messages), `comparison_bag` (the comparison bag
and the markers it shares with the stream), `view` (the Foxglove WebSocket server) and `layout`
(the Foxglove layout, written again by `python -m cloth_bench_ros.live.layout FILE`).
"""

from cloth_bench_ros.live.comparison_bag import write_comparison_bag
from cloth_bench_ros.live.view import LAYOUT_FILE, LiveView, LiveViewError

__all__ = ['LAYOUT_FILE', 'LiveView', 'LiveViewError', 'write_comparison_bag']
