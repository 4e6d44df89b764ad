"""Figure of global localisation: the particle cloud as it converges, error and particle count over time.

Usage: nice .venv/bin/python benchmarks/localization_figure.py [--world PNG|office] [--seed 1]
       [--out docs/img/localization_global.png]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np


def main(argv: list[str]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from slam2d.localization import KnownMap, ParticleFilter, preset
    from slam2d.localization.scenario import converged_at, replay, wander
    from slam2d.sim.world import load_world

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--world", default="office")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default="docs/img/localization_global.png")
    args = ap.parse_args(argv)
    world = load_world(args.world)
    known = KnownMap.from_world(world) if args.world == "office" else KnownMap.load(args.world)
    stream = wander(world, known, 30.0, args.seed)
    pf = ParticleFilter(known, preset("slam2d"), 12.0, seed=args.seed)
    pf.init_global()
    initial = pf.particles.copy()
    track = replay(pf, stream, "updates")
    kept = sorted(track.snapshots)
    conv = converged_at(track)
    conv = conv if conv is not None else kept[-1]
    mid = kept[min(np.searchsorted(kept, (kept[0] + conv) // 2), len(kept) - 1)]
    picks = {"first update": kept[0], "converging": mid, "converged": kept[min(np.searchsorted(kept, conv),
                                                                              len(kept) - 1)]}  # fmt: skip
    fig, axes = plt.subplots(1, 5, figsize=(22, 4.2), gridspec_kw={"width_ratios": [1, 1, 1, 1, 1.2]})
    x0, x1, y0, y1 = known.extent
    image = np.where(known.occupied, 0.0, np.where(known.free, 1.0, 0.8))
    panels = [("uniform start", initial[:: max(1, len(initial) // 2000)], None)]
    panels += [(name, track.snapshots[i][0], i) for name, i in picks.items()]
    for ax, (name, particles, i) in zip(axes[:4], panels):
        ax.imshow(image, cmap="gray", origin="lower", extent=(x0, x1, y0, y1), vmin=0, vmax=1,
                  interpolation="nearest")  # fmt: skip
        ax.plot(particles[:, 0], particles[:, 1], ".", ms=1.5, color="tab:blue", alpha=0.6)
        k = 0 if i is None else i
        ax.plot(*stream.truth[k, :2], "o", mfc="none", mec="tab:red", ms=10)
        n = len(pf.particles) if i is None else track.particles[i]
        when = "" if i is None else f", t = {stream.stamps[i] - stream.stamps[0]:.1f} s"
        ax.set_title(f"{name}{when}: {len(initial) if i is None else n} particles", fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    t = stream.stamps - stream.stamps[0]
    ax = axes[4]
    ax.semilogy(t, np.maximum(track.position_error, 1e-3), label="position error (m)")
    ax.semilogy(t, track.particles, label="particles")
    ax.axhline(0.2, color="0.5", ls=":", lw=0.8)
    ax.set_xlabel("t (s)")
    ax.legend(fontsize=8)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=90, bbox_inches="tight")
    print(args.out)


if __name__ == "__main__":
    main(sys.argv[1:])
