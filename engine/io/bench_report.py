"""The bench's report: report.md (tables), results.json (raw), and PNG plots (matplotlib, Agg)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def write_bench(results: dict, out: Path) -> list[Path]:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / "results.json"]
    paths[0].write_text(json.dumps(results, indent=2, default=float))
    md = [f"# tryon bench{' (quick)' if results.get('quick') else ''}", "",
          f"Machine: {results['machine']['cpus']} CPUs, Python {results['machine']['python']}; total "
          f"{results['total_seconds']:.0f} s (" + ", ".join(f"{k} {v:.0f} s" for k, v in
                                                          results["section_seconds"].items()) + ").", ""]
    if "table1" in results:
        md += _table1(results["table1"])
    if "sweeps" in results:
        md += _sweeps(results["sweeps"])
        paths.append(_pareto(results["sweeps"], out / "pareto.png"))
    if "scaling" in results:
        md += _scaling(results["scaling"])
        paths.append(_scaling_plot(results["scaling"], out / "scaling.png"))
    if "stability" in results:
        md += _stability(results["stability"])
        paths.append(_stability_plot(results["stability"], out / "stability.png"))
    if "peer" in results:
        md += _peer(results["peer"])
    p = out / "report.md"
    p.write_text("\n".join(md) + "\n")
    paths.insert(0, p)
    return paths


def _table1(rows) -> list[str]:
    md = ["## Seed 003 Table 1 layout: image space vs object space", "",
          "Sewing + draping on default:female, size M, cotton (set-up -- maps, BVH -- not counted, as in the seed). "
          "Seed: SGI R12000, 2001.", "",
          "| product | collision | vertices | iterations | total s | ms/it | cloth ms/it | collision ms/it | "
          "pen. max mm | strain % | seed vertices | seed iterations | seed total s | seed ms/it |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        s = r["seed"]
        if "failed" in r:
            md.append(f"| {r['product']} | {r['collision']} | failed: {r['failed'][:120]} | | | | | | | | "
                      f"{s[0]} | {s[1]} | {s[2]} | {s[3]} |")
            continue
        md.append(f"| {r['product']} | {r['collision']} | {r['vertices']} | {r['iterations']} | {r['total_s']:.1f} | "
                  f"{r['ms_per_iteration']:.2f} | {r['ms_cloth']:.2f} | {r['ms_collision']:.2f} | "
                  f"{r['penetration_max_mm']:.1f} | {100 * r['strain_max']:.1f} | {s[0]} | {s[1]} | {s[2]} | {s[3]} |")
    return md + [""]


def _sweeps(sw) -> list[str]:
    ref = sw["reference"]
    md = ["## Error against run time", "",
          f"The {sw['garment']} on default:female; base setting: cloth edge {sw['base_edge_cm']:g} cm, texel 5 mm, "
          f"the eq. 4 time step; one setting changed at a time. Distance: each vertex's distance to the surface of "
          f"a reference run (edge {ref['h'] * 100:g} cm, texel {ref['texel'] * 1000:g} mm, dt {ref['dt_fraction']:g} "
          f"x bound; {ref['vertices']} vertices, {ref['run_s']:.0f} s). Penetration measured exactly against the body "
          "mesh.", "",
          "| collision | changed | edge cm | texel mm | dt x bound | vertices | run s | distance mean mm | p95 mm | "
          "pen. max mm | pen. p99 mm | strain % | settled |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in sw["runs"]:
        tx = "-" if r["texel_mm"] is None else f"{r['texel_mm']:g}"
        if "failed" in r:
            md.append(f"| {r['collision']} | {r['axis']} | {r['edge_cm']:g} | {tx} | {r['dt_fraction']:g} | "
                      f"failed: {r['failed'][:100]} | | | | | | | |")
            continue
        md.append(f"| {r['collision']} | {r['axis']} | {r['edge_cm']:g} | {tx} | {r['dt_fraction']:g} | {r['vertices']} | "
                  f"{r['run_s']:.1f} | {r['distance_mean_mm']:.1f} | {r['distance_p95_mm']:.1f} | "
                  f"{r['penetration_max_mm']:.1f} | {r['penetration_p99_mm']:.1f} | {100 * r['strain_max']:.1f} | "
                  f"{r['settled']} |")
    return md + ["", "![error against run time](pareto.png)", ""]


def _pareto(sw, path: Path) -> Path:
    plt = _plt()
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    marks = {"texel": "o", "dt": "s", "edge": "^"}
    for col, colour in (("image", "tab:blue"), ("object", "tab:red")):
        rows = [r for r in sw["runs"] if r["collision"] == col and "failed" not in r]
        for axis, m in marks.items():
            rr = [r for r in rows if r["axis"] == axis]
            if rr:
                ax[0].scatter([r["run_s"] for r in rr], [r["distance_mean_mm"] for r in rr], c=colour, marker=m,
                              label=f"{col}: {axis}")
                ax[1].scatter([r["run_s"] for r in rr], [max(r["penetration_max_mm"], 0.01) for r in rr], c=colour,
                              marker=m)
        pts = sorted((r["run_s"], r["distance_mean_mm"]) for r in rows)
        front, best = [], np.inf
        for t, d in pts:
            if d < best:
                front.append((t, d))
                best = d
        if front:
            ax[0].plot(*zip(*front), c=colour, lw=1, alpha=0.6)
    ax[0].set_xscale("log")
    ax[0].set_xlabel("run time (s)")
    ax[0].set_ylabel("distance from reference, mean (mm)")
    ax[0].set_title("error against run time (line: Pareto front)")
    ax[0].legend(fontsize=7)
    ax[1].set_xscale("log")
    ax[1].set_yscale("log")
    ax[1].set_xlabel("run time (s)")
    ax[1].set_ylabel("penetration max (mm)")
    ax[1].set_title("penetration (exact) against run time")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _scaling(sc) -> list[str]:
    md = ["## Scaling", "", "ms per iteration of the sewing stage (skirt, default:female).", "",
          "| collision | cloth vertices | ms/it |", "|---|---|---|"]
    for r in sc["cloth"]:
        md.append(f"| {r['collision']} | {r['vertices']} | {r['ms_per_iteration']:.2f} |")
    for col, f in sc["fits"].items():
        md.append(f"\n{col}: {f['ms_per_1000_vertices']:.3f} ms per 1000 vertices + {f['intercept_ms']:.2f} ms, "
                  f"R² = {f['r2']:.3f}")
    md += ["", "| body | triangles | image ms/it | maps s | object ms/it | BVH s |", "|---|---|---|---|---|---|"]
    for r in sc["bodies"]:
        md.append(f"| {r['body']} | {r['triangles']} | {r['image_ms_per_iteration']:.2f} | {r['image_setup_s']:.2f} | "
                  f"{r['object_ms_per_iteration']:.2f} | {r['object_setup_s']:.2f} |")
    return md + ["", "![scaling](scaling.png)", ""]


def _scaling_plot(sc, path: Path) -> Path:
    plt = _plt()
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    for col, colour in (("image", "tab:blue"), ("object", "tab:red")):
        rr = [r for r in sc["cloth"] if r["collision"] == col]
        if rr:
            x = np.array([r["vertices"] for r in rr])
            ax[0].plot(x, [r["ms_per_iteration"] for r in rr], "o-", c=colour, label=col)
        b = sc["bodies"]
        ax[1].plot([r["triangles"] for r in b], [r[f"{col}_ms_per_iteration"] for r in b], "o-", c=colour, label=col)
    ax[0].set_xlabel("cloth vertices")
    ax[0].set_ylabel("ms per iteration")
    ax[0].set_title("against cloth size")
    ax[0].legend()
    ax[1].set_xscale("log")
    ax[1].set_xlabel("body triangles")
    ax[1].set_ylabel("ms per iteration")
    ax[1].set_title("against body size (skirt, 3 cm cloth)")
    ax[1].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _stability(st) -> list[str]:
    md = ["## Stability map", "",
          "The coarse skirt (3 cm), dressed in cotton, then 0.3 s with the cell's stiffness (x cotton as simulated), "
          "time step (x the eq. 4 bound for that stiffness) and body speed (m/s; 0 = standing). Cells: stable "
          "(strain max in brackets), refused (a clear error), unstable "
          f"(a bug). **Unstable cells: {st['unstable']}.**", ""]
    for s in st["speed"]:
        md += [f"Speed {s:g} m/s:", "", "| stiffness \\ dt | " + " | ".join(f"{f:g}" for f in st["dt_fraction"]) + " |",
               "|---|" + "---|" * len(st["dt_fraction"])]
        for k in st["stiffness"]:
            row = []
            for f in st["dt_fraction"]:
                c = next(c for c in st["cells"] if c["stiffness"] == k and c["dt_fraction"] == f and c["speed"] == s)
                row.append(c["outcome"] + (f" ({100 * c['strain_max']:.0f} %)" if "strain_max" in c else ""))
            md.append(f"| x{k:g} | " + " | ".join(row) + " |")
        md.append("")
    reasons = sorted({c["reason"][:140] for c in st["cells"] if c.get("reason")})
    if reasons:
        md += ["Reasons given:", ""] + [f"- {r}" for r in reasons] + [""]
    return md + ["![stability](stability.png)", ""]


def _stability_plot(st, path: Path) -> Path:
    plt = _plt()
    code = {"stable": 0, "refused": 1, "unstable": 2}
    fig, axes = plt.subplots(1, len(st["speed"]), figsize=(4 * len(st["speed"]), 3.6), squeeze=False)
    from matplotlib.colors import ListedColormap

    cmap = ListedColormap(["#4caf50", "#9e9e9e", "#e53935"])
    for ax, s in zip(axes[0], st["speed"]):
        grid = np.zeros((len(st["stiffness"]), len(st["dt_fraction"])))
        for i, k in enumerate(st["stiffness"]):
            for j, f in enumerate(st["dt_fraction"]):
                c = next(c for c in st["cells"] if c["stiffness"] == k and c["dt_fraction"] == f and c["speed"] == s)
                grid[i, j] = code[c["outcome"]]
        ax.imshow(grid, cmap=cmap, vmin=0, vmax=2, origin="lower")
        ax.set_xticks(range(len(st["dt_fraction"])), [f"{f:g}" for f in st["dt_fraction"]])
        ax.set_yticks(range(len(st["stiffness"])), [f"x{k:g}" for k in st["stiffness"]])
        ax.set_xlabel("dt / eq. 4 bound")
        ax.set_ylabel("stiffness")
        ax.set_title(f"speed {s:g} m/s")
    fig.suptitle("green stable, grey refused, red unstable")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _peer(p) -> list[str]:
    md = ["## A peer: Newton/Warp cloth on the CPU", ""]
    if not p.get("available"):
        return md + [f"Not run: {p.get('reason')}.", ""]
    md += [p.get("note", ""), "", "| solver | vertices | ms per step | first-run compile s |", "|---|---|---|---|"]
    for r in p["rows"]:
        md.append(f"| {r['solver']} | {r['vertices']} | {r['ms_per_step']:.3f} | {r.get('compile_s', 0):.1f} |")
    return md + [""]
