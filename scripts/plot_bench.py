#!/usr/bin/python3
"""Plots and a markdown table from `btfc bench --csv` output (one or more CSV files).

  scripts/plot_bench.py OUT_DIR run1.csv [run2.csv ...] [--doc docs/benchmarks.md]

Writes, per data set (the CSV's `data` column), PNG and SVG:
  rd_psnr-<data>   bits per value vs PSNR, one line per codec (rate-distortion)
  rd_ssim-<data>   bits per value vs mean SSIM over the BTF images
  pareto-<data>    encode time vs PSNR, Pareto front (faster and better) marked
  throughput       random interpolated evaluations per second per run
With --doc FILE, the section between '<!-- bench-table:begin -->' and '<!-- bench-table:end -->'
in FILE is replaced by a table of every run and links to the plots (created at the end of the
file when the markers are missing), so docs/benchmarks.md is regenerated from the CSV alone.
Needs python3-matplotlib (Debian).
"""
import csv
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def load(paths):
    rows = []
    for p in paths:
        with open(p, newline="") as f:
            rows.extend(csv.DictReader(f))
    for r in rows:
        for k in ("payload_bytes", "ratio", "bits_per_value", "rmse", "psnr", "mean_ssim", "encode_s", "decode_s",
                  "evals_per_s", "peak_rss_mb"):
            r[k] = float(r[k]) if r[k] not in ("", "inf") else (math.inf if r[k] == "inf" else math.nan)
        r["render_ssim"] = float(r["render_ssim"]) if r["render_ssim"] else math.nan
        r["codec"] = r["spec_given"].split(":")[0]
    return rows


def save(fig, out_dir, name):
    for ext in ("png", "svg"):
        fig.savefig(os.path.join(out_dir, f"{name}.{ext}"), dpi=110, bbox_inches="tight")
    plt.close(fig)


def safe(s):
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in s)


def rd_plot(rows, data, metric, label, out_dir):
    fig, ax = plt.subplots(figsize=(6, 4))
    for codec in sorted({r["codec"] for r in rows}):
        pts = sorted((r["bits_per_value"], r[metric]) for r in rows if r["codec"] == codec and math.isfinite(r[metric]))
        if pts:
            ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", label=codec)
    ax.set_xscale("log")
    ax.set_xlabel("bits per value (payload)")
    ax.set_ylabel(label)
    ax.set_title(f"{data}: rate-distortion")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    save(fig, out_dir, f"rd_{metric}-{safe(data)}")


def pareto_plot(rows, data, out_dir):
    fig, ax = plt.subplots(figsize=(6, 4))
    for codec in sorted({r["codec"] for r in rows}):
        sel = [r for r in rows if r["codec"] == codec]
        ax.scatter([r["encode_s"] for r in sel], [r["psnr"] for r in sel], label=codec)
    front, best = [], -math.inf
    for r in sorted(rows, key=lambda r: (r["encode_s"], -r["psnr"])):
        if r["psnr"] > best:
            front.append(r)
            best = r["psnr"]
    ax.plot([r["encode_s"] for r in front], [r["psnr"] for r in front], "k--", label="Pareto front")
    ax.set_xscale("log")
    ax.set_xlabel("encode time (s)")
    ax.set_ylabel("PSNR (dB)")
    ax.set_title(f"{data}: encode time vs quality")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    save(fig, out_dir, f"pareto-{safe(data)}")


def throughput_plot(rows, out_dir):
    fig, ax = plt.subplots(figsize=(7, 0.35 * len(rows) + 1.2))
    names = [f"{r['data']}: {r['spec_given']}" for r in rows]
    ax.barh(range(len(rows)), [r["evals_per_s"] / 1e6 for r in rows])
    ax.set_yticks(range(len(rows)), names, fontsize=7)
    ax.invert_yaxis()
    ax.set_xlabel("random interpolated evaluations per second (millions)")
    ax.set_title("decode throughput")
    save(fig, out_dir, "throughput")


def table(rows, out_dir, doc_dir):
    rel = os.path.relpath(out_dir, doc_dir)
    lines = [
        "| data | codec | ratio | bits/value | RMSE | PSNR dB | SSIM | rendered SSIM | encode s | decode s | M evals/s | peak MB |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['data']} | `{r['spec_given']}` | {r['ratio']:.1f} | {r['bits_per_value']:.4f} | {r['rmse']:.4g} | "
                     f"{r['psnr']:.2f} | {r['mean_ssim']:.4f} | {r['render_ssim']:.4f} | {r['encode_s']:.2f} | "
                     f"{r['decode_s']:.3f} | {r['evals_per_s'] / 1e6:.2f} | {r['peak_rss_mb']:.0f} |")
    cmds = sorted({r["command"] for r in rows})
    lines += ["", f"Machine: {rows[0]['machine']}; btfc {rows[0]['btfc_version']}; kernels on {rows[0]['device']}.",
              "Commands:", ""] + [f"    {c}" for c in cmds] + [""]
    for data in sorted({r["data"] for r in rows}):
        lines.append(f"![rate-distortion {data}]({rel}/rd_psnr-{safe(data)}.png) "
                     f"![SSIM {data}]({rel}/rd_mean_ssim-{safe(data)}.png) ![Pareto {data}]({rel}/pareto-{safe(data)}.png)")
    lines.append(f"![throughput]({rel}/throughput.png)")
    lines += ["", "### Which codec wins at equal bytes", winners(rows)]
    return "\n".join(lines)


# Budgets of the "which codec wins at equal bytes" table, as compression ratios (raw bytes /
# payload bytes, the CSV's ratio column).
BUDGET_RATIOS = (25, 50, 100, 200, 500)
METRICS = (("rmse", "RMSE", min, "{:.4g}"), ("psnr", "PSNR dB", max, "{:.2f}"), ("mean_ssim", "MSSIM", max, "{:.4f}"))


def winners(rows):
    """Per data set, metric and byte budget: each codec's best run whose payload fits the budget
    (ratio >= the budget's ratio), and the codec that wins. A codec with no run that small is '-'."""
    lines = []
    for data in sorted({r["data"] for r in rows}):
        sel = [r for r in rows if r["data"] == data]
        codecs = sorted({r["codec"] for r in sel})
        for key, label, better, fmt in METRICS:
            lines += ["", f"**{data}, {label}** (best run of each codec whose payload fits the budget; winner in bold)", "",
                      "| budget | " + " | ".join(f"`{c}`" for c in codecs) + " | winner |",
                      "|---|" + "---|" * (len(codecs) + 1)]
            for budget in BUDGET_RATIOS:
                best = {}
                for c in codecs:
                    fit = [r for r in sel if r["codec"] == c and r["ratio"] >= budget and math.isfinite(r[key])]
                    if fit:
                        best[c] = better(fit, key=lambda r: r[key])
                if not best:
                    continue
                win = better(best, key=lambda c: best[c][key])
                cells = []
                for c in codecs:
                    if c not in best:
                        cells.append("-")
                        continue
                    v = fmt.format(best[c][key]) + f" ({best[c]['ratio']:.0f}:1)"
                    cells.append(f"**{v}**" if c == win else v)
                lines.append(f"| 1:{budget} | " + " | ".join(cells) + f" | `{best[win]['spec_given']}` |")
    return "\n".join(lines)


def main(argv):
    doc = None
    if "--doc" in argv:
        i = argv.index("--doc")
        doc = argv[i + 1]
        argv = argv[:i] + argv[i + 2:]
    if len(argv) < 2:
        print(__doc__, file=sys.stderr)
        return 1
    out_dir, paths = argv[0], argv[1:]
    os.makedirs(out_dir, exist_ok=True)
    rows = load(paths)
    if not rows:
        print("plot_bench: no runs in " + ", ".join(paths), file=sys.stderr)
        return 2
    for data in sorted({r["data"] for r in rows}):
        sel = [r for r in rows if r["data"] == data]
        rd_plot(sel, data, "psnr", "PSNR (dB)", out_dir)
        rd_plot(sel, data, "mean_ssim", "mean SSIM (BTF images)", out_dir)
        pareto_plot(sel, data, out_dir)
    throughput_plot(rows, out_dir)
    if doc:
        text = open(doc).read() if os.path.exists(doc) else ""
        begin, end = "<!-- bench-table:begin -->", "<!-- bench-table:end -->"
        block = f"{begin}\n{table(rows, out_dir, os.path.dirname(os.path.abspath(doc)))}\n{end}"
        if begin in text and end in text:
            text = text[:text.index(begin)] + block + text[text.index(end) + len(end):]
        else:
            text = text.rstrip("\n") + "\n\n## All codecs, measured by `btfc bench` (regenerated by scripts/bench-all.sh)\n\n" + block + "\n"
        with open(doc, "w") as f:
            f.write(text)
    print(f"plot_bench: {len(rows)} runs -> {out_dir}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
