#!/usr/bin/python3
"""Draw PNG plots from one JSON document written by `hemirad bench --json`
(`plot.py scale FILE`: from bench/scale.sh's JSON)."""
import argparse
import json
import os
import sys

try:
    import matplotlib
except ImportError:
    sys.exit("plot.py: needs matplotlib (Debian: apt install python3-matplotlib, then run /usr/bin/python3)")

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter  # noqa: E402

STAGES = ("setup", "scan", "scatter", "raster", "read")
ROW_KEYS = ("engine", "device", "scene", "triangles", "hemicube", "ms_per_shot")
RUN_KEYS = ("seconds", "rms_rel_error", "sweep")
ANALYTIC_KEYS = ("case", "hemicube", "patch_size", "rel_error")


class BadDocument(Exception):
    pass


def need(obj, keys, where):
    """Raise BadDocument unless obj is an object holding every key."""
    if not isinstance(obj, dict):
        raise BadDocument(f"{where} is not an object")
    missing = [k for k in keys if k not in obj]
    if missing:
        raise BadDocument(f"{where} lacks {', '.join(repr(k) for k in missing)}")


def positive(value, where):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
        raise BadDocument(f"{where} is {value!r}, not a positive number")


def listed(value, where):
    if not isinstance(value, list):
        raise BadDocument(f"{where} is not a list")
    return value


def validate(doc):
    need(doc, (), "the document")
    if "results" not in doc and "accuracy" not in doc:
        raise BadDocument("neither 'results' nor 'accuracy' is present")
    for i, row in enumerate(listed(doc.get("results", []), "results")):
        need(row, ROW_KEYS, f"results[{i}]")
        need(row["ms_per_shot"], ("median",), f"results[{i}].ms_per_shot")
        for key in ("triangles", "hemicube"):
            positive(row[key], f"results[{i}].{key}")
        positive(row["ms_per_shot"]["median"], f"results[{i}].ms_per_shot.median")
    if "accuracy" in doc:
        acc = doc["accuracy"]
        need(acc, (), "accuracy")
        for i, a in enumerate(listed(acc.get("analytic", []), "accuracy.analytic")):
            need(a, ANALYTIC_KEYS, f"accuracy.analytic[{i}]")
            positive(a["hemicube"], f"accuracy.analytic[{i}].hemicube")
        if "room" in acc:
            need(acc["room"], ("runs",), "accuracy.room")
            for i, run in enumerate(listed(acc["room"]["runs"], "accuracy.room.runs")):
                need(run, RUN_KEYS, f"accuracy.room.runs[{i}]")
                positive(run["seconds"], f"accuracy.room.runs[{i}].seconds")
                positive(run["rms_rel_error"], f"accuracy.room.runs[{i}].rms_rel_error")
            for name, run in acc["room"].get("presets", {}).items():
                need(run, ("seconds", "rms_rel_error"), f"accuracy.room.presets.{name}")


# ---------------------------------------------------------------------------------------------
# helpers

def short_scene(scene):
    return scene if scene.startswith("procedural:") else os.path.splitext(os.path.basename(scene))[0]


def series_key(row):
    return (row["engine"], row["device"])


def series_label(key):
    return f"{key[0]}: {key[1]}"


def colours(keys):
    cycle = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    return {k: cycle[i % len(cycle)] for i, k in enumerate(keys)}


def unique(values):
    return list(dict.fromkeys(values))


def footer_text(doc, extra=""):
    parts = []
    m = doc.get("machine")
    if isinstance(m, dict):
        parts.append(f"CPU: {m.get('cpu', '?')} ({m.get('hardware_threads', '?')} hardware threads)")
    if "version" in doc:
        parts.append(f"hemirad {doc['version']}")
    if extra:
        parts.append(extra)
    return "   |   ".join(parts)


def plain_log(ax, which="y", unit="", fmt=None):
    """Label a log axis (set after plotting) with plain numbers, at 1-2-5 steps if it spans little."""
    axis, (lo, hi) = (ax.yaxis, ax.get_ylim()) if which == "y" else (ax.xaxis, ax.get_xlim())
    axis.set_major_locator(LogLocator(subs=(1, 2, 5) if hi / lo < 300 else (1,)))
    axis.set_major_formatter(FuncFormatter(fmt or (lambda v, _: f"{v:g}{unit}")))
    axis.set_minor_formatter(NullFormatter())


def bar_scale(ax, values, unit=""):
    """Bars: a log y axis when the values span more than 20x, else a linear one from zero."""
    pos = [v for v in values if v > 0]
    if pos and max(pos) > 20 * min(pos):
        ax.set_yscale("log")
        plain_log(ax, unit=unit)
    else:
        ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}{unit}"))


def count_label(v, _=None):
    """1000 -> 1k, 2500000 -> 2.5M."""
    for div, suffix in ((1e6, "M"), (1e3, "k")):
        if v >= div:
            return f"{v / div:g}{suffix}"
    return f"{v:g}"


def panels(n, width=5.2, height=4.2, max_cols=3):
    cols = min(n, max_cols)
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(width * cols, height * rows), squeeze=False)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    return fig, list(axes.flat[:n])


def guide(ax, xs, ys, power, label):
    """Dashed grey y ∝ x^power line through the first point, for reading slopes (y limits kept).

    Call it once the axes are log-log and the data are drawn."""
    x0, x1 = min(xs), max(xs)
    y0 = min(y for x, y in zip(xs, ys) if x == x0)
    ylim = ax.get_ylim()
    ax.plot([x0, x1], [y0, y0 * (x1 / x0) ** power], ls="--", color="0.6", lw=1, label=label, zorder=0)
    ax.set_ylim(ylim)


def finish(fig, path, doc, title, extra="", legend=None):
    """Title and provenance line on top, the legend (if any) below the panels, then save."""
    h = fig.get_figheight()
    fig.suptitle(title, fontsize=12, y=1 - 0.08 / h, va="top")
    fig.text(0.5, 1 - 0.34 / h, footer_text(doc, extra), ha="center", va="top", fontsize=7.5, color="0.3")
    fig.tight_layout(pad=0.6, rect=(0, 0, 1, 1 - 0.5 / h))
    if legend:
        fig.legend(*legend, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=min(len(legend[1]), 2),
                   fontsize=8, frameon=False)
    fig.savefig(path, dpi=110, bbox_inches="tight", metadata={"Software": None})
    plt.close(fig)
    print(path)


def n_axis(ax, ns):
    """Log x axis labelled with the hemicube N values themselves."""
    ax.set_xscale("log")
    ax.set_xticks(ns, [str(n) for n in ns])
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("hemicube N (cells per side)")


def merged_legend(axes):
    seen = {}
    for ax in axes:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            seen.setdefault(lab, h)
    return list(seen.values()), list(seen.keys())


def ms_errors(rows):
    """Median ± σ, the lower bar clipped so it stays positive on a log axis."""
    med = [r["ms_per_shot"]["median"] for r in rows]
    sig = [m * r["ms_per_shot"].get("sigma_percent", 0.0) / 100 for m, r in zip(med, rows)]
    return med, [[min(s, 0.9 * m) for s, m in zip(sig, med)], sig]


# ---------------------------------------------------------------------------------------------
# throughput

def draw_series(ax, rows, x_key, key, colour):
    """One engine's ms/shot (median ± σ) against x_key, as a line, if it has any rows."""
    line = sorted((r for r in rows if series_key(r) == key), key=lambda r: r[x_key])
    if line:
        med, err = ms_errors(line)
        ax.errorbar([r[x_key] for r in line], med, yerr=err, marker="o", ms=4,
                    capsize=2, color=colour[key], label=series_label(key))


def plot_scaling_triangles(doc, rows, out, colour):
    ns = sorted(n for n in {r["hemicube"] for r in rows}
                if len({r["triangles"] for r in rows if r["hemicube"] == n}) > 1)
    if not ns:
        return "needs one hemicube N measured on more than one scene size"
    fig, axes = panels(len(ns))
    for ax, n in zip(axes, ns):
        at_n = [r for r in rows if r["hemicube"] == n]
        proc = [r for r in at_n if r["scene"].startswith("procedural:")]
        for key in colour:
            draw_series(ax, proc, "triangles", key, colour)
            files = [r for r in at_n if series_key(r) == key and not r["scene"].startswith("procedural:")]
            if files:
                ax.scatter([r["triangles"] for r in files], [r["ms_per_shot"]["median"] for r in files],
                           marker="D", s=30, facecolors="none", edgecolors=colour[key], zorder=3)
        for scene in unique(r["scene"] for r in at_n if not r["scene"].startswith("procedural:")):
            r = max((r for r in at_n if r["scene"] == scene), key=lambda r: r["ms_per_shot"]["median"])
            ax.annotate(short_scene(scene), (r["triangles"], r["ms_per_shot"]["median"]),
                        xytext=(0, 6), textcoords="offset points", ha="center", fontsize=7)
        ax.set(xscale="log", yscale="log", title=f"hemicube N = {n}",
               xlabel="triangles", ylabel="ms per shot (median ± σ)")
        if proc:
            guide(ax, [r["triangles"] for r in proc], [r["ms_per_shot"]["median"] for r in proc],
                  1, "∝ triangles (guide)")
        plain_log(ax)
        plain_log(ax, "x", fmt=count_label)
        ax.grid(True, which="both", alpha=0.25)
    handles, labels = merged_legend(axes)
    handles.append(plt.Line2D([], [], marker="D", ls="", mfc="none", mec="0.3"))
    labels.append("file scenes (hollow diamonds, labelled; not part of the lines)")
    finish(fig, os.path.join(out, "scaling_triangles.png"), doc,
           "Shot time against scene size (lines: procedural scenes)", legend=(handles, labels))


def plot_scaling_hemicube(doc, rows, out, colour):
    scenes = sorted(unique(r["scene"] for r in rows), key=lambda s: (
        min(r["triangles"] for r in rows if r["scene"] == s), s))
    scenes = [s for s in scenes if len({r["hemicube"] for r in rows if r["scene"] == s}) > 1]
    if not scenes:
        return "needs a scene measured at more than one hemicube N"
    fig, axes = panels(len(scenes))
    for ax, scene in zip(axes, scenes):
        at_s = [r for r in rows if r["scene"] == scene]
        for key in colour:
            draw_series(ax, at_s, "hemicube", key, colour)
        n_axis(ax, sorted({r["hemicube"] for r in at_s}))
        ax.set(yscale="log", ylabel="ms per shot (median ± σ)",
               title=f"{short_scene(scene)} ({at_s[0]['triangles']:,} triangles)")
        guide(ax, [r["hemicube"] for r in at_s], [r["ms_per_shot"]["median"] for r in at_s],
              2, "∝ N² (guide)")
        plain_log(ax)
        ax.grid(True, which="both", alpha=0.25)
    finish(fig, os.path.join(out, "scaling_hemicube.png"), doc, "Shot time against hemicube resolution",
           legend=merged_legend(axes))


def scene_order(rows):
    return sorted(unique(r["scene"] for r in rows),
                  key=lambda s: (min(r["triangles"] for r in rows if r["scene"] == s), s))


def plot_fraction_of_limit(doc, rows, out, colour):
    rows = [r for r in rows if isinstance(r.get("limit"), dict) and "fraction" in r["limit"]]
    if not rows:
        return "no row has a 'limit'"
    ns = sorted({r["hemicube"] for r in rows})
    keys = [k for k in colour if any(series_key(r) == k for r in rows)]
    most = max(len({r["scene"] for r in rows if r["hemicube"] == n}) for n in ns)
    fig, axes = panels(len(ns), width=max(6.0, 1.5 + max(1.3, 0.3 * len(keys)) * most), height=3.4, max_cols=1)
    width = 0.8 / len(keys)
    for ax, n in zip(axes, ns):
        at_n = [r for r in rows if r["hemicube"] == n]
        scenes = scene_order(at_n)
        for j, key in enumerate(keys):
            pts = [(i, r["limit"]["fraction"] * 100) for i, s in enumerate(scenes)
                   for r in at_n if r["scene"] == s and series_key(r) == key]
            if pts:
                ax.bar([i - 0.4 + width * (j + 0.5) for i, _ in pts], [p for _, p in pts], width,
                       color=colour[key], label=series_label(key))
        ax.set_xticks(range(len(scenes)), [short_scene(s) for s in scenes])
        ax.set(ylabel="% of calibrated limit", title=f"hemicube N = {n}")
        bar_scale(ax, [r["limit"]["fraction"] * 100 for r in rows], "%")  # one scale for all panels
        ax.grid(True, axis="y", which="both", alpha=0.25)
    limits = unique(r["limit"].get("device", "?") for r in rows)
    finish(fig, os.path.join(out, "fraction_of_limit.png"), doc,
           "Shot throughput as a fraction of the calibrated limit (higher is better)",
           extra="limit devices: " + "; ".join(limits), legend=merged_legend(axes))


def plot_opencl_stages(doc, rows, out, colour):
    rows = [r for r in rows if r["engine"] == "opencl" and isinstance(r.get("device_ms_per_shot"), dict)]
    if not rows:
        return "no OpenCL row has 'device_ms_per_shot'"
    devices = unique(r["device"] for r in rows)
    cases = sorted({(r["triangles"], r["scene"], r["hemicube"]) for r in rows})  # shared x axis
    fig, axes = plt.subplots(2 * len(devices), 1, sharex=True, squeeze=False,
                             figsize=(max(6.0, 1.5 + 0.4 * len(cases)), 1.0 + 4.0 * len(devices)),
                             gridspec_kw={"height_ratios": [1, 1.5] * len(devices)})
    stage_colours = plt.get_cmap("tab10").colors
    for d, device in enumerate(devices):
        these = {(r["triangles"], r["scene"], r["hemicube"]): r for r in rows if r["device"] == device}
        xs = [i for i, c in enumerate(cases) if c in these]
        these = [these[cases[i]] for i in xs]
        totals = [sum(r["device_ms_per_shot"].get(s, 0.0) for s in STAGES) for r in these]
        top, share = axes[2 * d][0], axes[2 * d + 1][0]
        top.bar(xs, totals, 0.7, color="0.7", label="device ms/shot (sum of stages)")
        wall = [r["ms_per_shot"]["median"] for r in these]
        top.plot(xs, wall, "k_", ms=14, mew=2, label="wall-clock ms/shot (median)")
        top.set(ylabel="ms per shot", title=f"OpenCL device: {device}")
        bar_scale(top, totals + wall)
        bottom = [0.0] * len(these)
        for k, stage in enumerate(STAGES):
            pct = [100 * r["device_ms_per_shot"].get(stage, 0.0) / t if t else 0 for r, t in zip(these, totals)]
            share.bar(xs, pct, 0.7, bottom=bottom, color=stage_colours[k], label=stage)
            bottom = [a + b for a, b in zip(bottom, pct)]
        share.set(ylabel="% of device time", ylim=(0, 100))
        for ax in (top, share):
            ax.grid(True, axis="y", which="both", alpha=0.25)
    axes[-1][0].set_xticks(range(len(cases)), [f"{short_scene(s)}\nN={n}" for _, s, n in cases],
                           rotation=90 if len(cases) > 6 else 0, fontsize=8)
    axes[-1][0].set_xlim(-0.6, len(cases) - 0.4)
    finish(fig, os.path.join(out, "opencl_stages.png"), doc,
           "OpenCL time per shot: totals and the share of each stage (event profiling)",
           legend=merged_legend(axes[:2, 0]))


# ---------------------------------------------------------------------------------------------
# accuracy

def preset_star(ax, seconds, error, name):
    """A --quality preset on an error-against-time plot: a gold star and its name."""
    ax.scatter([seconds], [error], marker="*", s=260, color="gold", edgecolors="k", linewidths=0.8, zorder=5)
    ax.annotate(name, (seconds, error), xytext=(9, 6), textcoords="offset points", fontsize=10, weight="bold")


def error_time_axes(ax, ylabel):
    """Log-log axes of error against bake time, gridded, the legend to the right."""
    ax.set(xscale="log", yscale="log", xlabel="bake time (s)", ylabel=ylabel)
    plain_log(ax)
    plain_log(ax, "x")
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1), frameon=False)


def plot_accuracy_pareto(doc, acc, out):
    room = acc.get("room")
    if not room or not room["runs"]:
        return "no 'accuracy.room.runs'"
    runs = room["runs"]
    fig, ax = plt.subplots(figsize=(8, 6))
    for sweep in unique(r["sweep"] for r in runs):
        pts = [r for r in runs if r["sweep"] == sweep]
        ax.scatter([r["seconds"] for r in pts], [r["rms_rel_error"] for r in pts], s=22, alpha=0.8,
                   label=f"sweep: {sweep}")
    front = sorted((runs[i] for i in room.get("pareto", [])), key=lambda r: r["seconds"])
    if front:
        ax.step([r["seconds"] for r in front], [r["rms_rel_error"] for r in front], where="post",
                color="k", lw=1.2, label="Pareto front")
    for name, run in room.get("presets", {}).items():
        preset_star(ax, run["seconds"], run["rms_rel_error"], name)
    ax.scatter([], [], marker="*", s=120, color="gold", edgecolors="k", label="--quality presets")
    error_time_axes(ax, "RMS relative error of the radiosity")
    ref = room.get("reference", {})
    ref_text = ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                         for k, v in ref.items() if isinstance(v, (int, float, str)))
    finish(fig, os.path.join(out, "accuracy_pareto.png"), doc,
           f"Accuracy against time, room scene (device: {acc.get('device', '?')})",
           extra=f"reference: {ref_text}" if ref_text else "")


def plot_accuracy_cornell(doc, acc, out):
    cornell = acc.get("cornell")
    if not cornell or not cornell.get("runs"):
        return "no 'accuracy.cornell.runs'"
    runs = cornell["runs"]
    fig, ax = plt.subplots(figsize=(8, 6))
    for sweep in unique(r["sweep"] for r in runs if r["sweep"] != "preset"):
        pts = [r for r in runs if r["sweep"] == sweep]  # in the setting's order, not the time's
        ax.plot([r["seconds"] for r in pts], [r["pixels"]["rms"] for r in pts], marker="o", ms=4, lw=1,
                alpha=0.8, label=f"sweep: {sweep}")
        for r in pts:
            ax.annotate(r["label"].split(", ")[-1], (r["seconds"], r["pixels"]["rms"]), xytext=(4, -9),
                        textcoords="offset points", fontsize=7, alpha=0.8)
    presets = sorted((r for r in runs if r["sweep"] == "preset"), key=lambda r: r["seconds"])
    ax.plot([r["seconds"] for r in presets], [r["pixels"]["rms"] for r in presets], color="k", lw=1.2,
            label="--quality presets")
    for r in presets:
        preset_star(ax, r["seconds"], r["pixels"]["rms"], r["label"])
    error_time_axes(ax, "per-pixel relative RMS error (reference noise removed)")
    ref = cornell.get("reference", {})
    finish(fig, os.path.join(out, "accuracy_cornell.png"), doc,
           f"Cornell box against a converged path tracer (device: {acc.get('device', '?')})",
           extra=f"reference: {ref.get('settings', {}).get('samples_per_pixel', '?')} paths a pixel, "
                 f"{ref.get('image', ['?', '?'])[0]}x{ref.get('image', ['?', '?'])[1]}")


def plot_accuracy_analytic(doc, acc, out):
    cases = unique(a["case"] for a in acc.get("analytic", []))
    if not cases:
        return "no 'accuracy.analytic' cases"
    colour = colours(sorted({a["patch_size"] for a in acc["analytic"]}))
    fig, axes = panels(len(cases))
    for ax, case in zip(axes, cases):
        these = [a for a in acc["analytic"] if a["case"] == case]
        for size in sorted({a["patch_size"] for a in these}):
            line = sorted((a for a in these if a["patch_size"] == size and a["rel_error"] != 0),
                          key=lambda a: a["hemicube"])
            ax.plot([a["hemicube"] for a in line], [abs(a["rel_error"]) for a in line], marker="o",
                    ms=4, color=colour[size], label=f"patch size {size:g}")
        n_axis(ax, sorted({a["hemicube"] for a in these}))
        exact = these[0].get("exact")
        ax.set(yscale="log", ylabel="|relative error| of the form factor",
               title=case + (f" (exact F = {exact:.4g})" if exact is not None else ""))
        plain_log(ax)
        ax.grid(True, which="both", alpha=0.25)
    finish(fig, os.path.join(out, "accuracy_analytic.png"), doc,
           f"Form factors against closed forms (device: {acc.get('device', '?')})",
           extra="runs with zero error are not drawn (log axis)", legend=merged_legend(axes))


# ---------------------------------------------------------------------------------------------

SCALE_KEYS = ("kind", "count", "triangles", "quality", "status", "wall_s", "peak_rss_bytes")
# The targets: (kind or None for any, triangles, quality, seconds).
SCALE_TARGETS = (("city", 150e3, "default", 300), (None, 1e6, "draft", 900), ("furniture", 15e3, "default", 30))
KIND_MARKERS = {"city": "s", "furniture": "o", "foliage": "^"}


def validate_scale(doc):
    need(doc, ("runs",), "the document")
    for i, r in enumerate(listed(doc["runs"], "runs")):
        need(r, SCALE_KEYS, f"runs[{i}]")
        for key in ("triangles", "wall_s", "peak_rss_bytes"):
            positive(r[key], f"runs[{i}].{key}")


def plot_scale(doc, out, prefix):
    """Bake time and peak memory against triangles and against elements, one series per kind and quality.

    A bake stopped at the timeout is drawn hollow at the time it had run (a lower bound); bakes
    without a report (stopped, failed) have no elements and are left off the elements panels."""
    runs = doc["runs"]
    keys = unique((r["kind"], r["quality"]) for r in runs)
    colour = colours(unique(r["kind"] for r in runs))
    device = doc.get("machine", {}).get("device", "").split("|")[0].strip()  # the id and name, not the details
    extra = "; ".join(x for x in (device, doc.get("note", ""), "hollow: stopped at the timeout (a lower bound)") if x)
    for what, key, unit, title in (("time", "wall_s", " s", "Bake wall time"),
                                   ("memory", "peak_rss_bytes", "", "Peak resident memory")):
        fig, axes = panels(2)
        for ax, x_key, x_label in ((axes[0], "triangles", "triangles"), (axes[1], "elements", "elements (after refinement)")):
            for kind, quality in keys:
                rows = sorted((r for r in runs if r["kind"] == kind and r["quality"] == quality and r.get(x_key)),
                              key=lambda r: r[x_key])
                if not rows:
                    continue
                xs = [r[x_key] for r in rows]
                ys = [r[key] / (2**20 if what == "memory" else 1) for r in rows]
                ax.plot(xs, ys, color=colour[kind], lw=1, ls="-" if quality == "default" else "--",
                        label=f"{kind}, {quality}")
                for x, y, r in zip(xs, ys, rows):
                    ax.plot([x], [y], marker=KIND_MARKERS.get(kind, "o"), color=colour[kind],
                            mfc=colour[kind] if r["status"] == "ok" else "none", ms=6)
            if what == "time" and x_key == "triangles":
                for kind, tris, quality, seconds in SCALE_TARGETS:
                    ax.plot([tris], [seconds], marker="v", color="0.3", ms=7, ls="none",
                            label="targets" if kind == SCALE_TARGETS[0][0] else None)
                    ax.annotate(f"{kind or 'any'} {count_label(tris)} {quality}", (tris, seconds), fontsize=6.5,
                                xytext=(4, 4), textcoords="offset points", color="0.3")
            if what == "memory" and x_key == "elements":
                xs = [r["elements"] for r in runs if r.get("elements")]
                if xs:
                    lo, hi = min(xs), max(xs)
                    ax.plot([lo, hi], [2048 * lo / 2**20, 2048 * hi / 2**20], ls="--", color="0.6", lw=1,
                            label="target: 2 KB per element", zorder=0)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel(x_label)
            ax.set_ylabel("seconds (wall)" if what == "time" else "MiB (peak RSS)")
            plain_log(ax, "x", fmt=count_label)
            plain_log(ax, "y", unit=unit)
            ax.grid(True, which="major", color="0.9")
            ax.set_title(f"{title} against {x_key}")
        finish(fig, os.path.join(out, f"{prefix}_{what}.png"), doc, f"{title} against scene size",
               extra, merged_legend(axes))


def main_scale(argv):
    parser = argparse.ArgumentParser(prog="plot.py scale",
                                     description="Plot bake time and peak memory from bench/scale.sh's JSON.")
    parser.add_argument("json", help="file written by bench/scale.sh")
    parser.add_argument("--out", help="folder for the PNG files (default: the JSON's folder)")
    parser.add_argument("--prefix", default="scale", help="file names: PREFIX_time.png, PREFIX_memory.png")
    args = parser.parse_args(argv)
    try:
        with open(args.json, encoding="utf-8") as f:
            doc = json.load(f)
        validate_scale(doc)
    except (OSError, json.JSONDecodeError, BadDocument) as e:
        print(f"plot.py: {args.json}: {e}", file=sys.stderr)
        sys.exit(2)
    out = args.out or os.path.dirname(os.path.abspath(args.json))
    os.makedirs(out, exist_ok=True)
    plt.rcParams.update({"font.size": 9, "axes.titlesize": 10})
    plot_scale(doc, out, args.prefix)


def main():
    if sys.argv[1:2] == ["scale"]:
        return main_scale(sys.argv[2:])
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("json", help="file written by `hemirad bench --json`")
    parser.add_argument("--out", help="folder for the PNG files (default: the JSON's folder)")
    args = parser.parse_args()

    def fail(problem):
        print(f"plot.py: {args.json}: {problem}", file=sys.stderr)
        sys.exit(2)

    try:
        with open(args.json, encoding="utf-8") as f:
            doc = json.load(f)
        validate(doc)
    except OSError as e:
        fail(e.strerror or str(e))
    except json.JSONDecodeError as e:
        fail(f"not valid JSON ({e})")
    except BadDocument as e:
        fail(str(e))

    out = args.out or os.path.dirname(os.path.abspath(args.json))
    os.makedirs(out, exist_ok=True)
    plt.rcParams.update({"font.size": 9, "axes.titlesize": 10})
    rows = doc.get("results", [])
    colour = colours(unique(series_key(r) for r in rows))
    plots = []
    if rows:
        plots += [(f, (doc, rows, out, colour)) for f in
                  (plot_scaling_triangles, plot_scaling_hemicube, plot_fraction_of_limit, plot_opencl_stages)]
    if "accuracy" in doc:
        plots += [(f, (doc, doc["accuracy"], out)) for f in (plot_accuracy_pareto, plot_accuracy_cornell, plot_accuracy_analytic)]
    try:
        for plot, plot_args in plots:
            skipped = plot(*plot_args)
            if skipped:
                print(f"plot.py: skipped {plot.__name__[5:]}.png: {skipped}", file=sys.stderr)
    except (KeyError, TypeError, ValueError, IndexError, ZeroDivisionError) as e:
        fail(f"unexpected document layout in {plot.__name__[5:]} ({type(e).__name__}: {e})")


if __name__ == "__main__":
    main()
