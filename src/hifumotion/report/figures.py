"""The report's pictures (matplotlib, PNG, written atomically).

Each function takes plain data and a path and returns the path; none needs a display.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: Colours of the methods in every plot (physics red as in Fig. 4; truth green).
COLOURS = {"physics": "tab:red", "no_motion": "tab:grey", "kalman": "tab:blue", "ncc": "tab:purple",
           "truth": "tab:green", "drive_static": "tab:orange", "drive_lagged": "tab:brown", "surrogate": "tab:orange"}


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: str | Path) -> Path:
    from hifumotion.io.files import atomic_path

    plt = _pyplot()
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
    return path


def mesh_picture(vertices_mm: np.ndarray, faces: np.ndarray, path: str | Path, title: str = "",
                 views=((20, -60), (20, 30))) -> Path:
    """The reconstructed surface seen from two sides, Lambert-shaded (light from the viewer's upper left).

    Tank axes: x across, y up (drawn as the vertical axis), z along the sweep; mm."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    plt = _pyplot()
    v = np.asarray(vertices_mm, float)[:, [0, 2, 1]]     # y up on the plot's vertical axis
    tri = v[np.asarray(faces)]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    fig = plt.figure(figsize=(5.0 * len(views), 4.4))
    lo, hi = v.min(0), v.max(0)
    centre, half = (lo + hi) / 2, (hi - lo).max() / 2
    for i, (elev, azim) in enumerate(views):
        ax = fig.add_subplot(1, len(views), i + 1, projection="3d")
        e, a = np.radians(elev), np.radians(azim)
        light = np.array([np.cos(e) * np.cos(a - 0.6), np.cos(e) * np.sin(a - 0.6), np.sin(e + 0.5)])
        shade = 0.25 + 0.75 * np.clip(np.abs(normals @ (light / np.linalg.norm(light))), 0, 1)
        colours = np.column_stack([0.85 * shade, 0.45 * shade, 0.40 * shade, np.ones_like(shade)])
        ax.add_collection3d(Poly3DCollection(tri, facecolors=colours, edgecolors="none", linewidths=0))
        for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre):
            setter(c - half, c + half)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev, azim)
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("z (mm)")
        ax.set_zlabel("y (mm)")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def dsc_per_frame(frames, physics, baselines: dict, path: str | Path, training=(), validation=()) -> Path:
    """Table 4 as a plot: the physics' DSC per frame, the baselines' on the validation frames."""
    return _per_frame(frames, physics, baselines, path, training, validation, "DSC", "lower left")


def centroid_error_per_frame(frames, physics, baselines: dict, path: str | Path, training=(), validation=()) -> Path:
    """Where each predictor would aim: the centroid error (mm) per frame, the physics' and the
    baselines' (on the validation frames)."""
    return _per_frame(frames, physics, baselines, path, training, validation, "centroid error (mm)", "upper left")


def _per_frame(frames, physics, baselines: dict, path, training, validation, ylabel: str, legend: str) -> Path:
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 3.6))
    if len(training) and len(validation):
        half = 0.5 * (np.diff(sorted(training)).min() if len(training) > 1 else 1)
        ax.axvspan(min(training) - half, max(training) + half, color="0.93", zorder=0)
        ax.text(np.mean(training), 1.0, "training", ha="center", va="top", fontsize=9, transform=ax.get_xaxis_transform())
        ax.text(np.mean(validation), 1.0, "validation", ha="center", va="top", fontsize=9,
                transform=ax.get_xaxis_transform())
    ax.plot(frames, physics, "o-", color=COLOURS["physics"], label="physics (fitted model)")
    for name, (f, d) in baselines.items():
        ax.plot(f, d, "s--", color=COLOURS.get(name, None), label=name.replace("_", " "), markersize=4)
    ax.set_xlabel("frame")
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=8, loc=legend)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return _save(fig, path)


def aim_trajectory(times_s, aim_shift_mm: np.ndarray, path: str | Path, true_shift_mm: np.ndarray | None = None,
                   true_times_s=None, validation_from_s: float | None = None,
                   band_shift_mm: np.ndarray | None = None) -> Path:
    """Where to aim: the predicted shift of the aim point from the plan (x, y in mm) against
    time, beside the true section's centroid shift when known; ``band_shift_mm`` ``(2, F, 2)``,
    the shifts one standard error either way along the least determined direction, shaded."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 3.4))
    shift = np.asarray(aim_shift_mm, float)
    if band_shift_mm is not None:
        b = np.asarray(band_shift_mm, float)
        n = min(len(times_s), b.shape[1])
        both = np.concatenate([b[:, :n], shift[None, :n]])
        for axis, label in ((0, "±1 σ, least determined direction"), (1, None)):
            axes[0].fill_between(np.asarray(times_s)[:n], both[:, :, axis].min(0), both[:, :, axis].max(0),
                                 color=COLOURS["physics"], alpha=0.2, lw=0, label=label)
    axes[0].plot(times_s, shift[:, 0], color=COLOURS["physics"], label="predicted x")
    axes[0].plot(times_s, shift[:, 1], color=COLOURS["physics"], ls="--", label="predicted y (depth)")
    if true_shift_mm is not None:
        t = np.asarray(true_shift_mm, float)
        axes[0].plot(true_times_s, t[:, 0], color=COLOURS["truth"], label="true centroid x")
        axes[0].plot(true_times_s, t[:, 1], color=COLOURS["truth"], ls="--", label="true centroid y")
    if validation_from_s is not None:
        axes[0].axvline(validation_from_s, color="0.5", lw=0.8)
    axes[0].set_xlabel("time (s)")
    axes[0].set_ylabel("shift from the plan (mm)")
    axes[0].legend(fontsize=7)
    axes[0].grid(alpha=0.3)
    axes[1].plot(shift[:, 0], shift[:, 1], color=COLOURS["physics"], label="predicted")
    if true_shift_mm is not None:
        axes[1].plot(t[:, 0], t[:, 1], color=COLOURS["truth"], label="true centroid")
    axes[1].set_xlabel("x shift (mm)")
    axes[1].set_ylabel("y shift (mm)")
    axes[1].set_aspect("equal", adjustable="datalim")
    axes[1].legend(fontsize=7)
    axes[1].grid(alpha=0.3)
    fig.tight_layout()
    return _save(fig, path)


def online_horizons(online: dict, path: str | Path) -> Path:
    """The online mode: DSC and centroid error against the horizon (ms), per method."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 3.4))
    entries = sorted(online.values(), key=lambda e: e["horizon_ms"])
    ms = [e["horizon_ms"] for e in entries]
    for name in [m for m in ("physics", "no_motion", "ncc", "kalman", "surrogate") if all(m in e for e in entries)]:
        dsc = [e[name].get("dsc_mean", np.nan) for e in entries]
        cen = [e[name].get("centroid_mean_mm", np.nan) for e in entries]
        axes[0].plot(ms, dsc, "o-", color=COLOURS[name], label=name.replace("_", " "))
        axes[1].plot(ms, cen, "o-", color=COLOURS[name], label=name.replace("_", " "))
    axes[0].set_ylabel("DSC (mean)")
    axes[1].set_ylabel("centroid error (mm, mean)")
    for ax in axes:
        ax.set_xlabel("horizon (ms)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


__all__ = ["mesh_picture", "dsc_per_frame", "centroid_error_per_frame", "aim_trajectory", "online_horizons", "online_figure",
           "latency_axis_ms"]


def latency_axis_ms(latency_ms) -> tuple[float, int, float]:
    """The range a latency histogram is drawn over, so one stall does not squeeze every other
    frame into its first bar: up to the larger of the 99th percentile and 3 × the median (ms);
    with the frames beyond it and the largest latency (ms), which the figure states."""
    lat = np.asarray(latency_ms, float)
    lat = lat[np.isfinite(lat)]
    if lat.size == 0:
        return 1.0, 0, float("nan")
    upper = max(float(np.percentile(lat, 99)), 3.0 * float(np.median(lat)), 1e-3)
    return upper, int((lat > upper).sum()), float(lat.max())


def online_figure(result, path: str | Path, truth_mm: np.ndarray | None = None,
                  true_scale: np.ndarray | None = None) -> Path:
    """The online loop (:class:`~hifumotion.prediction.online.OnlineResult`): the predicted
    centroid at t + k (longest horizon) against the tracked (and the true, where known) one over
    time, the push's estimated scale (and the true one, ``true_scale`` per frame, where known),
    and the histogram of each frame's latency."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(12.0, 3.4))
    dt = result.frame_interval_s
    k = max(result.predicted_mm)
    times = np.arange(len(result.tracked_mm)) * dt
    target = (result.frames + k) * dt
    origin = result.tracked_mm[0]
    for c, style in ((0, "-"), (1, "--")):
        axis = "x" if c == 0 else "y (depth)"
        axes[0].plot(target, result.predicted_mm[k][:, c] - origin[c], color=COLOURS["physics"], ls=style,
                     label=f"predicted {k} frames ahead, {axis}")
        axes[0].plot(times, result.tracked_mm[:, c] - origin[c], color="0.4", ls=style, label=f"tracked, {axis}")
        if truth_mm is not None:
            t = np.asarray(truth_mm, float)
            axes[0].plot(times[:len(t)], t[:, c] - t[0, c], color=COLOURS["truth"], ls=style, label=f"true, {axis}")
    axes[0].set_xlabel("time (s)")
    axes[0].set_ylabel("centroid shift from frame 0 (mm)")
    axes[0].legend(fontsize=6)
    axes[0].grid(alpha=0.3)
    axes[1].plot(result.frames * dt, result.scale, color=COLOURS["physics"])
    axes[1].fill_between(result.frames * dt, result.scale - result.scale_std, result.scale + result.scale_std,
                         color=COLOURS["physics"], alpha=0.2)
    if true_scale is not None:
        t = np.asarray(true_scale, float)
        axes[1].plot(np.arange(len(t)) * dt, t, color=COLOURS["truth"], ls="--", label="true")
        axes[1].plot([], [], color=COLOURS["physics"], label="estimated")
        axes[1].legend(fontsize=6)
    axes[1].set_xlabel("time (s)")
    axes[1].set_ylabel("push / calibrated push")
    axes[1].grid(alpha=0.3)
    upper, beyond, largest = latency_axis_ms(result.latency_ms)
    axes[2].hist(np.clip(result.latency_ms, 0, upper), bins=30, range=(0, upper), color=COLOURS["physics"])
    if beyond:
        axes[2].set_title(f"{beyond} frame{'s' if beyond > 1 else ''} beyond {upper:.0f} ms (longest "
                          f"{largest:.0f} ms), drawn in the last bar", fontsize=8)
    axes[2].set_xlabel("latency a frame, tracking included (ms)")
    axes[2].set_ylabel("frames")
    axes[2].grid(alpha=0.3)
    fig.tight_layout()
    return _save(fig, path)
