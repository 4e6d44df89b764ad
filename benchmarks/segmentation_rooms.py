"""Room segmentation on the ipa benchmark maps: spectral clustering beside the established baselines.

For every map of ``rooms/`` (10 floor plans of Bormann et al., ICRA 2016),
without and with furniture, run spectral clustering with each similarity
measure and the morphological, distance-transform and Voronoi baselines, in
the same run on the same machine, and score them against the ground truth
(per-room recall and precision, %, as ``slam2d.segmentation.evaluate``).
Prints one Markdown table per setting (rows: method; recall and precision
averaged over maps, rooms found / in GT summed over maps, the silhouette-chosen
k (median over maps, spectral), wall and CPU seconds per map (medians; CPU time
is the fairer figure on a shared machine)) and writes every map's numbers to a
CSV. At most two worker processes, one BLAS thread each.

    nice .venv/bin/python benchmarks/segmentation_rooms.py [--data DIR] [--jobs 2]
        [--methods spectral morphological distance voronoi] [--similarities ...]
        [--maps office_a lab_ipa ...] [--setting both|plain|furnished] [--csv PATH]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor, as_completed  # noqa: E402
from pathlib import Path  # noqa: E402

DEFAULT_DATA = Path(os.environ.get("SLAM2D_DATA", Path(__file__).resolve().parents[1] / ".." / "shared" / "datasets"))
MAPS = ("Freiburg52_scan", "Freiburg79_scan", "lab_b_scan", "lab_c_scan", "lab_d_scan", "lab_ipa",
        "office_a", "office_b", "office_c", "office_d")  # fmt: skip
SIMILARITIES = ("hausdorff", "nearest_neighbour", "feature_points", "visibility")
BASELINE_NAMES = ("morphological", "distance", "voronoi")
PUBLISHED = {  # Bormann et al. 2016, 20 maps: (recall, precision) plain, furnished; seconds per map
    "morphological": ((98.1, 88.5), (84.6, 90.5), 1.6),
    "distance": ((96.9, 88.4), (76.1, 88.4), 1.8),
    "voronoi": ((95.0, 94.8), (86.6, 94.5), 13.0),
    "feature-based": ((89.2, 90.4), (85.1, 87.1), 269.0),
}
FIELDS = ("map", "furnished", "method", "similarity", "recall", "precision", "rooms_found", "rooms_gt", "k",
          "silhouette", "seconds", "cpu_seconds", "error")  # fmt: skip


def run_one(job: dict) -> dict:
    """Segment one map with one method and score it; a failure is returned as a row with ``error``."""
    import numpy as np

    from slam2d.segmentation.evaluate import load_floor_plan, load_ground_truth, score

    row = dict(job, recall=None, precision=None, rooms_found=None, rooms_gt=None, k=None, silhouette=None,
               seconds=None, cpu_seconds=None, error="")  # fmt: skip
    del row["path"], row["gt"]
    try:
        free, res = load_floor_plan(job["path"])
        gt = load_ground_truth(job["gt"])
        if job["method"] == "spectral":
            from slam2d.segmentation.spectral import segment_spectral

            cpu0 = time.process_time()
            r = segment_spectral(free, res, similarity=job["similarity"])
            labels, row["k"], row["silhouette"], row["seconds"] = r.labels, int(r.k), float(r.silhouette), r.seconds
        else:
            from slam2d.segmentation.baselines import BASELINES

            cpu0, t0 = time.process_time(), time.perf_counter()
            labels = BASELINES[job["method"]](free, res)
            row["seconds"] = time.perf_counter() - t0
        row["cpu_seconds"] = time.process_time() - cpu0
        row.update(score(np.asarray(labels), gt))
    except Exception as exc:  # keep the other runs going; the row records why
        row["error"] = f"{type(exc).__name__}: {exc}"
    return row


def make_jobs(data: Path, maps, methods, similarities, settings) -> list[dict]:
    """One job per (map, setting, method[, similarity]), spectral first (longest)."""
    rooms = data / "rooms"
    jobs = []
    for method in methods:
        for sim in (similarities if method == "spectral" else [""]):
            for name in maps:
                for furnished in settings:
                    path = rooms / (name + ("_furnitures" if furnished else "") + ".png")
                    gt = rooms / f"{name}_gt_segmentation.png"
                    if not path.is_file() or not gt.is_file():
                        sys.exit(f"{path if not path.is_file() else gt}: not found (set --data or SLAM2D_DATA)")
                    jobs.append(dict(map=name, furnished=furnished, method=method, similarity=sim,
                                     path=str(path), gt=str(gt)))  # fmt: skip
    return jobs


def _label(row: dict) -> str:
    return f"spectral / {row['similarity']}" if row["method"] == "spectral" else row["method"]


def _fmt(x, spec=".1f") -> str:
    return "–" if x is None else format(x, spec)


def table(rows: list[dict], furnished: bool) -> str:
    """Markdown table over maps of one setting: mean recall / precision, summed rooms, median k and seconds."""
    out = ["| method | recall % | precision % | rooms found / GT | k (median) | s per map | CPU s per map | maps |",
           "|---|---:|---:|---:|---:|---:|---:|---:|"]  # fmt: skip
    groups: dict[str, list[dict]] = {}
    for r in rows:
        if r["furnished"] == furnished:
            groups.setdefault(_label(r), []).append(r)
    for name, rs in groups.items():
        ok = [r for r in rs if not r["error"]]
        if not ok:
            out.append(f"| {name} | – | – | – | – | – | – | 0 / {len(rs)} |")
            continue
        ks = [r["k"] for r in ok if r["k"] is not None]
        out.append(
            f"| {name} | {statistics.mean(r['recall'] for r in ok):.1f} "
            f"| {statistics.mean(r['precision'] for r in ok):.1f} "
            f"| {sum(r['rooms_found'] for r in ok)} / {sum(r['rooms_gt'] for r in ok)} "
            f"| {_fmt(statistics.median(ks) if ks else None, 'g')} "
            f"| {statistics.median(r['seconds'] for r in ok):.2f} "
            f"| {statistics.median(r['cpu_seconds'] for r in ok):.2f} | {len(ok)} / {len(rs)} |"
        )
    return "\n".join(out)


def published_table() -> str:
    out = ["| method (Bormann et al. 2016, 20 maps) | plain R / P % | furnished R / P % | s per map |",
           "|---|---:|---:|---:|"]  # fmt: skip
    for name, ((r0, p0), (r1, p1), s) in PUBLISHED.items():
        out.append(f"| {name} | {r0} / {p0} | {r1} / {p1} | {s} |")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="dataset root holding rooms/")
    ap.add_argument("--maps", nargs="+", default=list(MAPS))
    ap.add_argument("--methods", nargs="+", default=["spectral", *BASELINE_NAMES],
                    choices=["spectral", *BASELINE_NAMES])  # fmt: skip
    ap.add_argument("--similarities", nargs="+", default=list(SIMILARITIES))
    ap.add_argument("--setting", choices=["both", "plain", "furnished"], default="both")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (1 or 2)")
    ap.add_argument("--csv", type=Path, default=Path("results") / "segmentation_rooms.csv")
    ap.add_argument("--config", type=Path, help="YAML with any of these options (e.g. experiments/ablation_segmentation.yaml)")
    pre, _ = ap.parse_known_args()
    if pre.config:
        import yaml

        options = yaml.safe_load(pre.config.read_text()) or {}
        unknown = set(options) - {a.dest for a in ap._actions}
        if unknown:
            ap.error(f"{pre.config}: unknown key '{sorted(unknown)[0]}'")
        ap.set_defaults(**options)
    args = ap.parse_args()
    if not 1 <= args.jobs <= 2:
        ap.error("--jobs must be 1 or 2 (the machine is shared)")
    methods = list(args.methods)
    if "spectral" in methods:
        try:
            import slam2d.segmentation.spectral  # noqa: F401
        except ImportError as exc:
            print(f"spectral segmentation unavailable ({exc}); running the baselines only", file=sys.stderr)
            methods.remove("spectral")
    settings = {"both": [False, True], "plain": [False], "furnished": [True]}[args.setting]
    jobs = make_jobs(args.data, args.maps, methods, args.similarities, settings)

    rows, t0 = [], time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        futures = [pool.submit(run_one, j) for j in jobs]
        for i, fut in enumerate(as_completed(futures), 1):
            r = fut.result()
            rows.append(r)
            state = r["error"] or f"R {r['recall']:.1f} P {r['precision']:.1f} {r['seconds']:.1f} s"
            print(f"[{i}/{len(jobs)}] {r['map']}{' furnished' if r['furnished'] else ''} {_label(r)}: {state}",
                  file=sys.stderr, flush=True)  # fmt: skip
    order = {(j["map"], j["furnished"], j["method"], j["similarity"]): i for i, j in enumerate(jobs)}
    rows.sort(key=lambda r: order[(r["map"], r["furnished"], r["method"], r["similarity"])])

    args.csv.parent.mkdir(parents=True, exist_ok=True)
    with args.csv.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS)
        w.writeheader()
        w.writerows(rows)
    for furnished in settings:
        print(f"\n### {'furnished' if furnished else 'no furniture'} ({len(args.maps)} maps)\n")
        print(table(rows, furnished))
    print("\n### published, for context\n")
    print(published_table())
    print(f"\nper-map rows: {args.csv}; wall time {time.perf_counter() - t0:.0f} s with {args.jobs} workers")


if __name__ == "__main__":
    main()
