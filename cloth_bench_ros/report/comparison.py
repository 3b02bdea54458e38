"""Showing a comparison: a bag Foxglove/RViz open, the paper's qualitative figure, an animation.

Input is what the evaluator kept of each scored real frame: its `FrameScore`, the real points and
the engine's vertices at that time. The bag holds, stamped in run time: the real cloud, each
engine's vertices (PointCloud2) and mesh (visualization_msgs/Marker TRIANGLE_LIST, red), the
gripper targets, per-frame metrics, and /tf_static for `world`. The figure puts the mesh (red)
over the real cloud (black) at the time steps of the paper's Fig. 4, CD/HD under each panel, one
row per engine; the animation shows the same over the whole trial (GIF; MP4 when ffmpeg exists).
"""

from __future__ import annotations

import shutil
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from cloth_bench_ros.core.scene import SETTLE_DURATION, ClothGrid
from cloth_bench_ros.core.trajectory import full_targets, quaternion_xyz
from cloth_bench_ros.data import messages
from cloth_bench_ros.data.bag_writer import BagWriter
from cloth_bench_ros.data.messages import DIAGNOSTIC_ARRAY, POSE_ARRAY, TYPESTORE

# The paper's Fig. 4: time steps (s from the start of the motion) of each primitive.
FIG4_TIMES = {"dynamic": (0.5, 1.5, 2.5, 3.5), "quasi_static": (1.0, 4.0, 8.0, 14.0)}
MARKER = "visualization_msgs/msg/Marker"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
REAL_TOPIC = "/cloth_bench/comparison/real/cloud"
TARGETS_TOPIC = "/cloth_bench/comparison/targets"
METRICS_TOPIC = "/cloth_bench/comparison/metrics"
ANIMATION_FRAMES = 60  # at most; frames are spread evenly over the trial


def default_message(msgtype: str, **values: Any) -> Any:
    """A rosbags message with every field at its ROS default, then `values` set."""
    _, fields = TYPESTORE.fielddefs[msgtype]
    kwargs: dict[str, Any] = {}
    for name, (kind, detail) in fields:
        if name in values:
            kwargs[name] = values[name]
        elif kind == 2:  # nested message
            kwargs[name] = default_message(detail)
        elif kind == 1:  # base type
            kwargs[name] = "" if detail[0] == "string" else False if detail[0] == "bool" else 0
        elif kind == 4 and detail[0][0] == 1:  # sequence of a base type
            kwargs[name] = np.zeros(0, dtype=np.uint8 if detail[0][1] in ("uint8", "octet") else np.float64)
        elif kind == 4:
            kwargs[name] = []
        else:  # fixed array
            kwargs[name] = np.zeros(detail[1])
    return messages.msg_class(msgtype)(**kwargs)


def grid_for(vertex_count: int) -> ClothGrid:
    """The cloth grid of an engine's vertex count: the default one, or the nx x nz closest to its shape."""
    default = ClothGrid()
    if vertex_count == default.nx * default.nz:
        return default
    aspect = default.nz / default.nx
    pairs = [(nx, vertex_count // nx) for nx in range(2, vertex_count) if vertex_count % nx == 0
             and vertex_count // nx >= 2]
    if not pairs:
        raise ValueError(f"{vertex_count} vertices do not form a cloth grid")
    nx, nz = min(pairs, key=lambda p: abs(p[1] / p[0] - aspect))
    return ClothGrid(nx, nz)


def _marker(stamp: int, engine: str, vertices: np.ndarray, faces: np.ndarray) -> Any:
    point = messages.msg_class("geometry_msgs/msg/Point")
    tris = vertices[faces.ravel()]
    return default_message(
        MARKER, header=messages.header(stamp), ns=engine, id=0, type=11, action=0,
        pose=default_message("geometry_msgs/msg/Pose", orientation=messages.msg_class(
            "geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=0.0, w=1.0)),
        scale=messages.msg_class("geometry_msgs/msg/Vector3")(x=1.0, y=1.0, z=1.0),
        color=messages.msg_class("std_msgs/msg/ColorRGBA")(r=1.0, g=0.0, b=0.0, a=0.8),
        points=[point(x=float(x), y=float(y), z=float(z)) for x, y, z in tris])


def _tf_static() -> Any:
    ts = default_message("geometry_msgs/msg/TransformStamped", header=messages.header(0, "world"),
                         child_frame_id="cloth_bench")
    ts.transform.rotation.w = 1.0
    return messages.msg_class(TF_MESSAGE)(transforms=[ts])


def _targets(primitive: str, rate_hz: float, stamp: int) -> Any:
    tg = full_targets(primitive, rate_hz)
    k = int(np.clip(round(stamp / 1e9 * rate_hz), 0, len(tg) - 1))
    pose = messages.msg_class("geometry_msgs/msg/Pose")
    qx, qy, qz, qw = quaternion_xyz(tg.roll[k], tg.pitch[k], tg.yaw[k])
    poses = []
    for p in (tg.left[k], tg.right[k]):
        poses.append(pose(position=messages.msg_class("geometry_msgs/msg/Point")(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                          orientation=messages.msg_class("geometry_msgs/msg/Quaternion")(x=qx, y=qy, z=qz, w=qw)))
    return messages.msg_class(POSE_ARRAY)(header=messages.header(stamp), poses=poses)


def _metrics(stamp: int, score: Any) -> Any:
    kv = messages.msg_class("diagnostic_msgs/msg/KeyValue")
    status = messages.msg_class("diagnostic_msgs/msg/DiagnosticStatus")(
        level=2 if score.diverged else 0, name=f"cloth_bench/{score.engine}/frame", message=f"frame {score.frame}",
        hardware_id=score.engine, values=[kv(key=k, value=repr(getattr(score, k))) for k in ("frame", "t", "cd", "hd")])
    return messages.msg_class(DIAGNOSTIC_ARRAY)(header=messages.header(stamp), status=[status])


def write_comparison_bag(path: Path, pairs: list, primitive: str, rate_hz: float) -> dict[str, int]:
    """The comparison bag (see module doc); returns messages per topic."""
    offset = int(round(SETTLE_DURATION * 1e9))
    with BagWriter(path) as bag:
        bag.write_message("/tf_static", _tf_static(), 0)
        real_done: set[int] = set()
        for score, real, vertices in pairs:
            stamp = offset + int(round(score.t * 1e9))
            if score.frame not in real_done:
                real_done.add(score.frame)
                bag.write_cloud(REAL_TOPIC, stamp, real)
                bag.write_message(TARGETS_TOPIC, _targets(primitive, rate_hz, stamp), stamp)
            engine = score.engine
            bag.write_cloud(f"/cloth_bench/comparison/{engine}/cloud", stamp, vertices)
            bag.write_message(f"/cloth_bench/comparison/{engine}/mesh",
                              _marker(stamp, engine, vertices, grid_for(len(vertices)).faces()), stamp)
            bag.write_message(METRICS_TOPIC, _metrics(stamp, score), stamp)
        return bag.close()


def _by_engine(pairs: list) -> dict[str, list]:
    out: dict[str, list] = defaultdict(list)
    for p in pairs:
        out[p[0].engine].append(p)
    return dict(out)


def _draw(ax: Any, real: np.ndarray, vertices: np.ndarray) -> None:
    """Side view (y right, z up), where the fling shows: cloud black, mesh red."""
    ax.scatter(real[:, 1], real[:, 2], s=0.5, c="black", linewidths=0)
    faces = grid_for(len(vertices)).faces()
    ax.triplot(vertices[:, 1], vertices[:, 2], faces, color="red", linewidth=0.4)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])


def qualitative_figure(pairs: list, primitive: str, path: Path) -> tuple[int, int]:
    """The paper's Fig. 4 for this run: (rows, columns) drawn = (engines, time steps)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    engines = _by_engine(pairs)
    times = FIG4_TIMES[primitive]
    fig, axes = plt.subplots(len(engines), len(times), figsize=(2.2 * len(times), 2.6 * len(engines)), squeeze=False)
    for row, (engine, rows) in enumerate(engines.items()):
        for col, t in enumerate(times):
            ax = axes[row][col]
            score, real, vertices = min(rows, key=lambda p: abs(p[0].t - t))
            _draw(ax, real, vertices)
            ax.set_xlabel(f"t={score.t:.1f} s\nCD {score.cd:.3f}  HD {score.hd:.3f}", fontsize=7)
            if col == 0:
                ax.set_ylabel(engine)
    fig.suptitle("simulated mesh (red) over the real cloud (black), side view (y-z)", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return len(engines), len(times)


def animation(pairs: list, path: Path) -> tuple[Path, int]:
    """Sim against real over the trial, one panel per engine: MP4 with ffmpeg, else GIF (PillowWriter)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FFMpegWriter, FuncAnimation, PillowWriter

    engines = _by_engine(pairs)
    count = min(len(rows) for rows in engines.values())
    picks = np.unique(np.linspace(0, count - 1, min(count, ANIMATION_FRAMES)).round().astype(int))
    fig, axes = plt.subplots(1, len(engines), figsize=(3 * len(engines), 3), squeeze=False)

    def update(i: int) -> None:
        for ax, (engine, rows) in zip(axes[0], engines.items()):
            ax.clear()
            score, real, vertices = rows[picks[i]]
            _draw(ax, real, vertices)
            ax.set_title(f"{engine} t={score.t:.2f} s CD {score.cd:.3f}", fontsize=7)

    anim = FuncAnimation(fig, update, frames=len(picks))
    if shutil.which("ffmpeg"):
        path = path.with_suffix(".mp4")
        anim.save(path, writer=FFMpegWriter(fps=10))
    else:
        path = path.with_suffix(".gif")
        anim.save(path, writer=PillowWriter(fps=10))
    plt.close(fig)
    return path, len(picks)


def write_comparison(pairs: list, summary: dict, bag_path: Path | None, figures_dir: Path | None) -> dict:
    """Every comparison output asked for; returns what was written, for the summary."""
    run = summary["run"]
    out: dict[str, Any] = {}
    if not pairs:
        return {"skipped": "no frame was scored"}
    if bag_path is not None:
        out["bag"] = str(bag_path)
        out["bag_topics"] = write_comparison_bag(bag_path, pairs, run["primitive"], float(run["rate_hz"]))
    if figures_dir is not None:
        figures_dir.mkdir(parents=True, exist_ok=True)
        fig_path = figures_dir / "qualitative.png"
        out["figure"], out["figure_panels"] = str(fig_path), qualitative_figure(pairs, run["primitive"], fig_path)
        anim_path, frames = animation(pairs, figures_dir / "animation")
        out["animation"], out["animation_frames"] = str(anim_path), frames
    return out


def comparison_section(doc: Any, results_dir: Path, out_dir: Path) -> list[Path]:
    """The report's hook: each run directory with a qualitative figure gets a section.

    Run directories are results_dir or one level below; the figure (`cloth-bench run --figures`)
    and its animation are copied to out_dir.
    """
    found = sorted({*results_dir.glob("qualitative.png"), *results_dir.glob("*/qualitative.png")})
    if not found:
        return []
    doc.h(2, "Qualitative comparison (the paper's Fig. 4)")
    doc.p("Simulated mesh in red over the real cloud in black at the paper's time steps, CD/HD (m) under each "
          "panel, one row per engine; the animation shows the whole trial.")
    copied = []
    for figure in found:
        run = figure.parent.name
        for src in [figure, *sorted(figure.parent.glob("animation.*"))]:
            dst = out_dir / f"{run}_{src.name}"
            shutil.copyfile(src, dst)
            copied.append(dst)
            doc.img(dst.name, f"{run}: {'qualitative figure' if src == figure else 'animation'}")
    return copied
