"""Spectral room segmentation on the rooms/ benchmark (Bormann et al. ICRA 2016 maps).

    nice .venv/bin/python benchmarks/segmentation_spectral.py [--similarity visibility ...] [--maps office_a ...]

Prints, per similarity measure and for the plain and furnished maps, one row a
map (recall / precision %, rooms found vs ground truth, k, wall and CPU
seconds of segment_spectral, map loading excluded) and the means. Furnished
maps are scored against the unfurnished ground truth.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

from slam2d.segmentation.evaluate import load_floor_plan, load_ground_truth, score
from slam2d.segmentation.similarity import SIMILARITIES
from slam2d.segmentation.spectral import segment_spectral

ROOT = Path(os.environ.get("SLAM2D_DATA", Path(__file__).resolve().parents[1] / ".." / "shared" / "datasets"))
MAPS = ["Freiburg52_scan", "Freiburg79_scan", "lab_b_scan", "lab_c_scan", "lab_d_scan", "lab_ipa",
        "office_a", "office_b", "office_c", "office_d"]


def run(name: str, furnished: bool, similarity: str, params: dict) -> dict:
    rooms = ROOT / "rooms"
    free, res = load_floor_plan(rooms / f"{name}{'_furnitures' if furnished else ''}.png")
    gt = load_ground_truth(rooms / f"{name}_gt_segmentation.png")
    r = segment_spectral(free, res, similarity, **params)
    sc = score(r.labels, gt)
    return dict(map=name, furnished=furnished, similarity=similarity, k=r.k, silhouette=r.silhouette,
                seconds=r.seconds, cpu=r.timings["cpu_total"], n_obs=len(r.observation_labels), **sc,
                cpu_stages={k: round(v, 3) for k, v in r.timings["cpu"].items()})


def table(rows: list[dict]) -> str:
    out = ["| map | recall | precision | rooms found / GT | k | wall s | CPU s |",
           "|---|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        out.append(f"| {r['map']} | {r['recall']:.1f} | {r['precision']:.1f} | {r['rooms_found']} / {r['rooms_gt']}"
                   f" | {r['k']} | {r['seconds']:.2f} | {r['cpu']:.2f} |")
    m = {k: np.mean([r[k] for r in rows]) for k in ("recall", "precision", "seconds", "cpu")}
    out.append(f"| **mean** | **{m['recall']:.1f}** | **{m['precision']:.1f}** | | "
               f"| {m['seconds']:.2f} | {m['cpu']:.2f} |")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--similarity", nargs="*", default=list(SIMILARITIES))
    ap.add_argument("--maps", nargs="*", default=MAPS)
    ap.add_argument("--furnished", choices=["no", "yes", "both"], default="both")
    ap.add_argument("--params", default="{}", help="JSON of SpectralConfig fields")
    ap.add_argument("--json", help="also write all rows to this file")
    a = ap.parse_args()
    params = json.loads(a.params)
    furn = {"no": [False], "yes": [True], "both": [False, True]}[a.furnished]
    for sim in a.similarity:  # compile the numba kernels outside the timings
        segment_spectral(np.pad(np.ones((40, 40), bool), 2), 0.05, sim)
    rows = []
    for sim in a.similarity:
        for f in furn:
            part = [run(m, f, sim, params) for m in a.maps]
            rows += part
            print(f"\n### {sim}, {'furnished' if f else 'no furniture'}\n")
            print(table(part), flush=True)
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    t = time.perf_counter()
    main()
    print(f"\ntotal {time.perf_counter() - t:.0f} s")
