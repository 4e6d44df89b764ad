"""The SLAM back end's final batch on the five Radish logs: Cauchy LM + the chi-square check (the
default) beside GNC and the g2o benchmarks' best outlier method, ``pc_dcs``.

Usage: .venv/bin/python benchmarks/slam_final_batch.py [intel aces fr079 fr-clinic csail]
       [--variants default gnc pc_dcs pc_dcs_phi10]

Everything before the final batch is the same in every variant (the loops are found, verified and
added by the same code; iSAM2 under the Cauchy kernel); only the last optimisation and the loops it
removes differ. ``pc_dcs`` runs through ``benchmarks/plugins/final_batch_pc_dcs.py``.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from slam_radish import PUBLISHED, run

PLUGIN = str(Path(__file__).resolve().parent / "plugins" / "final_batch_pc_dcs.py")
VARIANTS = {  # name: (overrides, plugins, DCS Phi)
    "default": ([], [], None),
    "gnc": (["backend.gnc=true"], [], None),
    "pc_dcs": ([], [PLUGIN], "1"),
    "pc_dcs_phi10": ([], [PLUGIN], "10"),
}


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="*", help=f"some of {', '.join(PUBLISHED)} (default: all)")
    ap.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=list(VARIANTS))
    args = ap.parse_args(argv)
    unknown = set(args.logs) - set(PUBLISHED)
    if unknown:
        ap.error(f"unknown log(s) {sorted(unknown)}; choose from {list(PUBLISHED)}")
    print("| log | final batch | trans. abs (m) | rot. abs (deg) | loops added | removed by the final batch |")
    print("|---|---|---|---|---|---|")
    for log in args.logs or list(PUBLISHED):
        for name in args.variants:
            overrides, plugins, phi = VARIANTS[name]
            env = {**os.environ, "SLAM2D_PC_DCS_PHI": phi} if phi else None
            m = run(log, [*overrides, "output.figures=false"], plugins, env)
            r, slam = m["relations"], m["slam"]
            print(f"| {log} | {name} | {r['trans_abs_mean']:.4f} ± {r['trans_abs_std']:.4f} "
                  f"| {r['rot_abs_mean']:.3f} ± {r['rot_abs_std']:.3f} | {slam['loop_closures_added']} "
                  f"| {slam['loop_closures_removed_as_inconsistent']} |", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
