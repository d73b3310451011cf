"""A figure per clip: the hand at a few frames, the 36 features and the 6 labels.

    python -m rtcohand_drake.data.plots --data PATH.h5 --clip USER/CLIP --out fig.png [--rate 10]

A missing or corrupt file, or an unknown clip, exits with status 2 and one line on stderr.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from rtcohand_drake.data.dataset import DIMENSIONS, Clip, DatasetError, find_clips, read_dataset, to_policy_clip
from rtcohand_drake.data.hand_features import FINGER_CHAINS, PARTS

# Bones of the 21-point skeleton: each finger chain from the wrist, plus the palm's knuckle line.
BONES = [(0, int(c[0])) for c in FINGER_CHAINS] + [
    (int(c[i]), int(c[i + 1])) for c in FINGER_CHAINS for i in range(3)
] + [(5, 9), (9, 13), (13, 17)]
DIM_COLOURS = ("tab:red", "tab:green", "tab:blue", "tab:red", "tab:green", "tab:blue")


def _draw_hand(ax, kp: np.ndarray, title: str) -> None:
    if not np.isfinite(kp).all():
        ax.set_title(title + " (hand lost)", fontsize=8)
        return
    for a, b in BONES:
        ax.plot(*kp[[a, b]].T, color="0.3", lw=1.5)
    ax.scatter(*kp.T, s=6, color="tab:blue")
    ax.set_title(title, fontsize=8)


def clip_figure(clip: Clip, rate_hz: float = 10.0, n_hands: int = 4):
    """A matplotlib figure of one clip (a `Figure`: a notebook shows it, `savefig` writes it)."""
    from matplotlib.figure import Figure  # no pyplot: the caller's backend (a notebook's) is left alone

    pc = to_policy_clip(clip, rate_hz)
    t = np.arange(len(pc)) / rate_hz
    fig = Figure(figsize=(12, 10), constrained_layout=True)
    grid = fig.add_gridspec(4, n_hands, height_ratios=[1.2, 1, 1, 1])
    dims = ", ".join(DIMENSIONS[d] for d in clip.active_dims) or "none"
    fig.suptitle(f"{clip.name}  ({clip.group}, {clip.split}; active: {dims})\n{clip.description}", fontsize=10)

    # Hands at a few frames, on common axes (user frame, metres).
    seen = np.flatnonzero(np.isfinite(clip.keypoints).all(axis=(1, 2)))
    frames = np.linspace(0, clip.num_frames - 1, n_hands).round().astype(int)
    if seen.size:
        pts = clip.keypoints[seen].reshape(-1, 3)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        centre, half = (lo + hi) / 2, max(float((hi - lo).max()) / 2, 0.06)
    for i, f in enumerate(frames):
        ax = fig.add_subplot(grid[0, i], projection="3d")
        _draw_hand(ax, clip.keypoints[f], f"t = {clip.times[f] - clip.times[0]:.1f} s")
        if seen.size:
            ax.set_xlim(centre[0] - half, centre[0] + half)
            ax.set_ylim(centre[1] - half, centre[1] + half)
            ax.set_zlim(centre[2] - half, centre[2] + half)
        ax.set_xlabel("X", fontsize=7)
        ax.set_ylabel("Y", fontsize=7)
        ax.set_zlabel("Z", fontsize=7)
        ax.tick_params(labelsize=6)
        ax.view_init(elev=25, azim=-70)

    x = pc.features.reshape(-1, 6, 6)
    rows = [f"{p} {a}" for p in PARTS for a in ("x", "y", "z")]
    for r, (name, sl, unit) in enumerate((("linear velocity", slice(0, 3), "m/s"), ("angular velocity", slice(3, 6), "rad/s"))):
        ax = fig.add_subplot(grid[1 + r, :])
        data = x[:, :, sl].reshape(len(pc), 18).T
        lim = max(float(np.percentile(np.abs(data), 99)), 1e-6)
        im = ax.imshow(data, aspect="auto", cmap="RdBu_r", vmin=-lim, vmax=lim, interpolation="nearest",
                       extent=(t[0] - 0.5 / rate_hz, t[-1] + 0.5 / rate_hz, 17.5, -0.5))
        ax.set_yticks(range(18), rows, fontsize=6)
        for k in range(1, 6):
            ax.axhline(3 * k - 0.5, color="0.5", lw=0.5)
        for k in np.flatnonzero(~pc.valid):
            ax.axvspan(t[k] - 0.5 / rate_hz, t[k] + 0.5 / rate_hz, color="0.8", alpha=0.8, lw=0)
        ax.set_title(f"features: {name} of each part's frame, user frame ({unit}; grey = hand lost)", fontsize=9)
        fig.colorbar(im, ax=ax, pad=0.01, label=unit)

    ax = fig.add_subplot(grid[3, :])
    if pc.labels is not None:
        ax2 = ax.twinx()
        for d in range(6):
            target = ax if d < 3 else ax2
            target.plot(t, pc.labels[:, d], color=DIM_COLOURS[d], ls="-" if d < 3 else "--",
                        lw=2.0 if d in clip.active_dims else 0.8, label=DIMENSIONS[d])
        ax.set_ylabel("translation (m/s), solid")
        ax2.set_ylabel("rotation (rad/s), dashed")
        lim_t = max(float(np.abs(pc.labels[:, :3]).max()), 0.02) * 1.1
        lim_r = max(float(np.abs(pc.labels[:, 3:]).max()), 0.1) * 1.1
        ax.set_ylim(-lim_t, lim_t)
        ax2.set_ylim(-lim_r, lim_r)
        h1, l1 = ax.get_legend_handles_labels()
        h2, l2 = ax2.get_legend_handles_labels()
        ax.legend(h1 + h2, l1 + l2, ncol=6, fontsize=7, loc="upper right")
    else:
        ax.text(0.5, 0.5, "no labels (unlabelled stream)", ha="center", transform=ax.transAxes)
    ax.axhline(0, color="0.6", lw=0.5)
    ax.set_xlabel("time (s)")
    ax.set_title(f"labels: workpiece twist from the handler, at {rate_hz:g} Hz (thick = active)", fontsize=9)
    return fig


def plot_clip(clip: Clip, out: str, rate_hz: float = 10.0) -> None:
    """Write the figure of one clip to ``out`` (any matplotlib format, e.g. .png)."""
    clip_figure(clip, rate_hz).savefig(out, dpi=110)


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:
        sys.stderr.write(f"{self.prog}: error: {' '.join(message.split())}\n")
        sys.exit(2)


def make_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="python -m rtcohand_drake.data.plots", description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, help="dataset file (.h5)")
    parser.add_argument("--clip", required=True, help="USER/CLIP")
    parser.add_argument("--out", required=True, help="figure file (.png, .pdf, ...)")
    parser.add_argument("--rate", type=float, default=10.0, help="policy rate, Hz")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = make_parser().parse_args(argv)
    try:
        clips = read_dataset(args.data)
    except DatasetError as err:
        sys.stderr.write(f"{err}\n")
        return 2
    found = find_clips(clips, args.clip) if "/" in args.clip else []
    if not found:
        sys.stderr.write(f"{args.data}: no clip {args.clip!r} (give USER/CLIP)\n")
        return 2
    try:
        plot_clip(found[0], args.out, args.rate)
    except OSError as err:
        sys.stderr.write(f"{args.out}: cannot write: {' '.join(str(err).split())}\n")
        return 2
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
