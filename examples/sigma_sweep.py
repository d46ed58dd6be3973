"""Section III.C of the extended Barrera et al. paper: error vs iteration when the object jumps 2 m, for a
sweep of sigma_m (the paper's Fig. 7), written as a table (errors.csv: sigma, iteration, mean error).

    python examples/sigma_sweep.py --device cpu --frames 100 --out sweep
"""

from __future__ import annotations

import argparse

from wptrack.core.device import quiet_warp
from wptrack.trackers.colour.experiments import default_sigmas, jump_experiment
from wptrack.trackers.colour.sweep import write_sweep


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))  # the whole sentence
    ap.add_argument("--device", default="auto")
    ap.add_argument("--frames", type=int, default=100, help="iterations per run (the jump happens at 30)")
    ap.add_argument("--steps", type=int, default=12, help="sigma_m values between 0.001 and 0.3 m")
    ap.add_argument("--runs", type=int, default=10, help="runs averaged per sigma_m")
    ap.add_argument("--particles", type=int, default=200)
    ap.add_argument("--out", default="sigma-sweep")
    args = ap.parse_args(argv)
    quiet_warp()
    sigmas = default_sigmas(args.steps)
    jump_at = min(30, args.frames // 2)
    table = jump_experiment(
        sigmas, particles=args.particles, iterations=args.frames, jump_at=jump_at, runs=args.runs, device=args.device
    )
    path = write_sweep(table, args.out)
    print(f"sigma_m [m]  iterations to converge: initially / after the 2 m jump at iteration {jump_at}")
    for row in table["summary"]:
        c0, c1 = row["converge_initial"], row["converge_after_jump"]
        first = str(c0) if c0 is not None else f"not within {jump_at}"
        after = str(c1) if c1 is not None else "not within the run"
        print(f"  {row['sigma']:8.4f}   {first} / {after}")
    print(f"table written to {path}")
    return table


if __name__ == "__main__":
    main()
