#!/usr/bin/python3
"""Plots of bench/bsvtf_bench.cpp output (docs/benchmarks.md, "BSVTF").

  scripts/plot_bsvtf.py OUT_DIR CSV_DIR LABEL [LABEL ...]

Reads CSV_DIR/bsvtf_{quality,cache,stream}_<LABEL>.csv and writes to OUT_DIR (PNG):
  bsvtf_quality.png  tile compression ratio (vs half-float tiles) against quality, and the
                     decoded BTF's SSIM against the fmf model (the paper: up to 6:1 with no
                     perceivable artifacts)
  bsvtf_cache.png    mean eigen-texture error and mean rendered SSIM against tile-cache size on
                     the fly-through path (seed 000 Fig. 4)
  bsvtf_stream.png   rendered SSIM against bytes streamed on the still path (seed 000 Fig. 5)
Needs python3-matplotlib (Debian).
"""
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def rows(path):
    with open(path, newline="") as f:
        return [{k: float(v) if v not in ("", "nan") else float("nan") for k, v in r.items()} for r in csv.DictReader(f)]


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    out, src, labels = sys.argv[1], sys.argv[2], sys.argv[3:]
    os.makedirs(out, exist_ok=True)

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    for lab in labels:
        q = rows(f"{src}/bsvtf_quality_{lab}.csv")
        a.plot([r["quality"] for r in q], [r["tile_ratio_half"] for r in q], "o-", label=lab)
        b.plot([r["tile_ratio_half"] for r in q], [r["btf_ssim_vs_fmf"] for r in q], "o-", label=lab + " (BTF images)")
        b.plot([r["tile_ratio_half"] for r in q], [r["render_ssim_vs_fmf"] for r in q], "x--", label=lab + " (render)")
    a.set(xlabel="quality", ylabel="tile ratio vs half-float tiles", yscale="log", title="DCT tile compression")
    a.axhline(6, color="grey", lw=0.8, ls=":")
    b.set(xlabel="tile ratio vs half-float tiles", ylabel="SSIM vs the fmf model", xscale="log", title="quality of the decoded BTF")
    b.axvline(6, color="grey", lw=0.8, ls=":")
    for ax in (a, b):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(f"{out}/bsvtf_quality.png", dpi=110)

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    for lab in labels:
        c = rows(f"{src}/bsvtf_cache_{lab}.csv")
        mb = [r["cache_bytes"] / 1e6 for r in c]
        a.plot(mb, [r["mean_error"] for r in c], "o-", label=lab)
        b.plot(mb, [r["mean_ssim"] for r in c], "o-", label=lab)
    a.set(xlabel="tile cache (MB, half floats)", ylabel="mean relative eigen-texture error", title="error vs cache size (fly path)")
    b.set(xlabel="tile cache (MB, half floats)", ylabel="mean SSIM vs converged render", title="SSIM vs cache size (fly path)")
    for ax in (a, b):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(f"{out}/bsvtf_cache.png", dpi=110)

    fig, ax = plt.subplots(figsize=(6, 4))
    for lab in labels:
        s = rows(f"{src}/bsvtf_stream_{lab}.csv")
        for n in sorted({r["cache_tiles"] for r in s}):
            pts = [r for r in s if r["cache_tiles"] == n]
            ax.plot([r["bytes"] / 1e6 for r in pts], [r["ssim"] for r in pts], ".-", label=f"{lab}, {int(n)} tiles")
    ax.set(xlabel="bytes streamed (MB)", ylabel="SSIM vs converged render", title="streaming (still view, bandwidth-limited)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(f"{out}/bsvtf_stream.png", dpi=110)


if __name__ == "__main__":
    main()
