#!/usr/bin/python3
"""Plots and a markdown table from `btfc bench --csv` output (one or more CSV files).

  scripts/plot_bench.py OUT_DIR run1.csv [run2.csv ...] [--doc docs/benchmarks.md] [--run CMD ...]

Writes, per data set (the CSV's `data` column), PNG and SVG:
  rd_psnr-<data>   bits per value vs PSNR, one line per setting (rate-distortion)
  rd_ssim-<data>   bits per value vs mean SSIM over the BTF images
  pareto-<data>    encode time vs PSNR, Pareto front (faster and better) marked
  throughput       random interpolated evaluations per second per run
With --doc FILE, the section between '<!-- bench-table:begin -->' and '<!-- bench-table:end -->'
in FILE is replaced by a table of every run and links to the plots (created at the end of the
file when the markers are missing), so docs/benchmarks.md is regenerated from the CSV alone.
Each --run CMD (repeatable) is a command listed before the CSV's own `command` column, e.g. the
scripts/bench-all.sh invocation and the commands that wrote its inputs.
Runs are grouped into settings: a codec with the parameters its sweep keeps fixed (`fmf`,
`fmf:precision=q:bits=6`, `fmf:color=dfmf`, ...), one line / column per setting, so a rank sweep
at half precision and one with quantized factors are not drawn as one curve.
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
    settings(rows)
    return rows


def params(spec):
    """'fmf:precision=q:rank=16' -> ('fmf', [('precision', 'q'), ('rank', '16')])."""
    parts = spec.split(":")
    return parts[0], [tuple(p.split("=", 1)) if "=" in p else (p, "") for p in parts[1:]]


def settings(rows):
    """Sets r['setting']: the codec and the parameters that do not vary among the runs with the
    same codec and the same parameter names (the sweep's knob, e.g. rank, is dropped)."""
    groups = {}
    for r in rows:
        codec, kv = params(r["spec_given"])
        groups.setdefault((codec, tuple(sorted(k for k, _ in kv))), []).append(r)
    for (codec, _), sel in groups.items():
        values = {}
        for r in sel:
            for k, v in params(r["spec_given"])[1]:
                values.setdefault(k, set()).add(v)
        for r in sel:
            fixed = [f"{k}={v}" if v else k for k, v in params(r["spec_given"])[1] if len(values[k]) == 1]
            r["setting"] = ":".join([codec] + fixed) if len(sel) > 1 else r["spec_given"]


def save(fig, out_dir, name):
    for ext in ("png", "svg"):
        fig.savefig(os.path.join(out_dir, f"{name}.{ext}"), dpi=110, bbox_inches="tight")
    plt.close(fig)


def safe(s):
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in s)


def rd_plot(rows, data, metric, label, out_dir):
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for i, setting in enumerate(sorted({r["setting"] for r in rows})):
        pts = sorted((r["bits_per_value"], r[metric]) for r in rows if r["setting"] == setting and math.isfinite(r[metric]))
        if pts:
            ax.plot([p[0] for p in pts], [p[1] for p in pts], "os^vD<>ph*"[i % 10] + ("-" if i < 10 else "--"),
                    label=setting)
    ax.set_xscale("log")
    ax.set_xlabel("bits per value (payload)")
    ax.set_ylabel(label)
    ax.set_title(f"{data}: rate-distortion")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    save(fig, out_dir, f"rd_{metric}-{safe(data)}")


def pareto_plot(rows, data, out_dir):
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for i, setting in enumerate(sorted({r["setting"] for r in rows})):
        sel = [r for r in rows if r["setting"] == setting]
        ax.scatter([r["encode_s"] for r in sel], [r["psnr"] for r in sel], marker="os^vD<>ph*"[i % 10], label=setting)
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
    ax.legend(fontsize=7)
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


def table(rows, out_dir, doc_dir, runs=()):
    rel = os.path.relpath(out_dir, doc_dir)
    lines = [
        "| data | codec | ratio | bits/value | RMSE | PSNR dB | SSIM | rendered SSIM | encode s | decode s | M evals/s | peak MB |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['data']} | `{r['spec_given']}` | {r['ratio']:.1f} | {r['bits_per_value']:.4f} | {r['rmse']:.4g} | "
                     f"{r['psnr']:.2f} | {r['mean_ssim']:.4f} | {r['render_ssim']:.4f} | {r['encode_s']:.2f} | "
                     f"{r['decode_s']:.3f} | {r['evals_per_s'] / 1e6:.2f} | {r['peak_rss_mb']:.0f} |")
    # In the order they ran (the CSV's order), with the paths as they were given.
    cmds = list(runs) + [c for c in dict.fromkeys(r["command"] for r in rows) if c not in runs]
    lines += ["", f"Machine: {rows[0]['machine']}; btfc {rows[0]['btfc_version']}; kernels on {rows[0]['device']}. "
              "Times are wall-clock on that machine, one run each.", "",
              "Commands, as run:", ""] + [f"    {c}" for c in cmds] + [""]
    for data in sorted({r["data"] for r in rows}):
        lines.append(f"![rate-distortion {data}]({rel}/rd_psnr-{safe(data)}.png) "
                     f"![SSIM {data}]({rel}/rd_mean_ssim-{safe(data)}.png) ![Pareto {data}]({rel}/pareto-{safe(data)}.png)")
    lines.append(f"![throughput]({rel}/throughput.png)")
    lines += ["", "### Which codec wins at equal bytes", "",
              "A budget 1:N allows a payload of raw float32 bytes / N; each cell is the best run of that setting "
              "(codec and the parameters its sweep keeps fixed) whose ratio is at least N, with its ratio. "
              "Settings whose runs all take more bytes than the budget show '-'.",
              winners(rows), leads(rows)]
    return "\n".join(lines)


# Budgets of the "which codec wins at equal bytes" table, as compression ratios (raw bytes /
# payload bytes, the CSV's ratio column).
BUDGET_RATIOS = (25, 50, 100, 200, 500)
METRICS = (("rmse", "RMSE", min, "{:.4g}"), ("psnr", "PSNR dB", max, "{:.2f}"), ("mean_ssim", "MSSIM", max, "{:.4f}"))
# The issue 22 goal: the best setting at a budget this many dB above plain half-float fmf at the same bytes.
LEAD_GOAL_DB = 3.0


def winners(rows):
    """Per data set, metric and byte budget: each setting's best run whose payload fits the budget
    (ratio >= the budget's ratio), and the setting that wins. A setting with no run that small is '-'."""
    lines = []
    for data in sorted({r["data"] for r in rows}):
        sel = [r for r in rows if r["data"] == data]
        setts = sorted({r["setting"] for r in sel})
        for key, label, better, fmt in METRICS:
            lines += ["", f"**{data}, {label}** (best run of each setting whose payload fits the budget; winner in bold)", "",
                      "| budget | " + " | ".join(f"`{c}`" for c in setts) + " | winner |",
                      "|---|" + "---|" * (len(setts) + 1)]
            for budget in BUDGET_RATIOS:
                best = {}
                for c in setts:
                    fit = [r for r in sel if r["setting"] == c and r["ratio"] >= budget and math.isfinite(r[key])]
                    if fit:
                        best[c] = better(fit, key=lambda r: r[key])
                if not best:
                    continue
                win = better(best, key=lambda c: best[c][key])
                cells = []
                for c in setts:
                    if c not in best:
                        cells.append("-")
                        continue
                    v = fmt.format(best[c][key]) + f" (1:{best[c]['ratio']:.0f})"
                    cells.append(f"**{v}**" if c == win else v)
                lines.append(f"| 1:{budget} | " + " | ".join(cells) + f" | `{best[win]['spec_given']}` |")
    return "\n".join(lines)


def plain_fmf(r):
    """fmf at half precision, rgb, plain eigen-textures: the reference of the lead table."""
    codec, kv = params(r["spec"])
    kv = dict(kv)
    return codec == "fmf" and kv.get("precision") == "half" and kv.get("color") == "rgb" and kv.get("textures", "plain") == "plain"


def interp_log(pts, x):
    """Linear interpolation of y in log(x) over the (x, y) points; None outside their range."""
    pts = sorted(pts)
    for (x0, y0), (x1, y1) in zip(pts, pts[1:]):
        if x0 <= x <= x1:
            return y0 if x1 == x0 else y0 + (y1 - y0) * math.log(x / x0) / math.log(x1 / x0)
    return pts[0][1] if len(pts) == 1 and x == pts[0][0] else None


def fmf_at(ref, ratio):
    """Plain fmf's PSNR at a ratio as (cell text, value, kind): kind '=' interpolated in log ratio
    between measured ranks, '>=' / '<=' a bound from the sweep's nearest end (fmf's PSNR rises with
    its bytes; not extrapolated), None without a value."""
    at = interp_log(ref, ratio)
    if at is not None:
        return f"{at:.2f}", at, "="
    if ratio < ref[0][0]:
        return f"n/a (>= {ref[0][1]:.2f} at 1:{ref[0][0]:.0f})", ref[0][1], ">="
    return f"n/a (<= {ref[-1][1]:.2f} at 1:{ref[-1][0]:.0f})", ref[-1][1], "<="


def lead_cell(psnr, fmf):
    """The lead over fmf and its kind: fmf '>=' a value makes the lead '<=' and the other way."""
    _, value, kind = fmf
    lead = psnr - value
    return {"=": f"{lead:+.2f}", ">=": f"<= {lead:+.2f}", "<=": f">= {lead:+.2f}"}[kind], lead, kind


def leads(rows):
    """Per data set with a plain fmf sweep: at each budget 1:N, the best PSNR run that fits it, and
    plain half-float fmf's PSNR both at 1:N (fmf filling the budget: the issue 22 goal) and at that
    run's own ratio (equal bytes). fmf's PSNR is interpolated in log ratio between the measured
    ranks; beyond them it is not extrapolated and the lead is bounded by the sweep's nearest end."""
    lines = []
    for data in sorted({r["data"] for r in rows}):
        sel = [r for r in rows if r["data"] == data and math.isfinite(r["psnr"])]
        ref = sorted((r["ratio"], r["psnr"]) for r in sel if plain_fmf(r))
        if len(ref) < 2:
            continue
        lines += ["", f"**{data}, PSNR lead over plain fmf** (plain fmf = half-float `fmf:rank=R`, measured from "
                  f"1:{ref[0][0]:.0f} to 1:{ref[-1][0]:.0f}, its PSNR interpolated in log ratio, not extrapolated; "
                  f"goal of issue 22: the best run that fits 1:N >= {LEAD_GOAL_DB:g} dB above plain fmf at 1:N)", "",
                  "| budget 1:N | best PSNR run that fits | its ratio | PSNR dB | plain fmf at 1:N, dB | lead at 1:N | "
                  "plain fmf at the run's ratio, dB | lead at equal bytes | goal |",
                  "|---|---|---:|---:|---:|---:|---:|---:|---|"]
        for budget in BUDGET_RATIOS:
            fit = [r for r in sel if r["ratio"] >= budget]
            if not fit:
                continue
            best = max(fit, key=lambda r: r["psnr"])
            at_budget, at_run = fmf_at(ref, budget), fmf_at(ref, best["ratio"])
            text, lead, kind = lead_cell(best["psnr"], at_budget)
            if kind == "=" or (kind == ">=" and lead < LEAD_GOAL_DB) or (kind == "<=" and lead >= LEAD_GOAL_DB):
                goal = "met" if lead >= LEAD_GOAL_DB else "not met"
            else:
                goal = "unknown (fmf not measured at 1:N)"
            lines.append(f"| 1:{budget} | `{best['spec_given']}` | 1:{best['ratio']:.0f} | {best['psnr']:.2f} | "
                         f"{at_budget[0]} | {text} | {at_run[0]} | {lead_cell(best['psnr'], at_run)[0]} | {goal} |")
    return "\n".join(lines)


def main(argv):
    doc = None
    if "--doc" in argv:
        i = argv.index("--doc")
        doc = argv[i + 1]
        argv = argv[:i] + argv[i + 2:]
    runs = []
    while "--run" in argv:
        i = argv.index("--run")
        runs.append(argv[i + 1])
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
        block = f"{begin}\n{table(rows, out_dir, os.path.dirname(os.path.abspath(doc)), runs)}\n{end}"
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
