#!/usr/bin/env bash
# Bake time and peak memory against scene size: for each generated content scene (city, furniture,
# foliage; src/gen/content_scenes.h) at each triangle count, writes it as .glb
# (`hemirad scene write`), bakes it with `hemirad bake` and records wall time, CPU time (user +
# sys), peak resident memory (the bake process's ru_maxrss, from wait4) and the patches, elements
# and passes of its report.json. Writes the results as JSON and a markdown table beside it (.md);
# `bench/plot.py scale` plots them. Bakes run one at a time, from a release build.
#   bench/scale.sh [options] [-- extra bake options]
#     --build DIR          the build directory (default build/release)
#     --kinds LIST         comma-separated kinds (default city,furniture,foliage)
#     --counts LIST        comma-separated triangle counts as the specs take them (default 10k,100k,1M,3M)
#     --quality Q          bake quality below --large-from triangles (default: default)
#     --large-quality Q    bake quality from --large-from up (default: draft)
#     --large-from N       where the large quality starts, in triangles (default 1000000)
#     --timeout S          seconds a bake may run before it is stopped (SIGTERM; default 3600).
#                          A stopped bake is recorded as "timeout" with its last progress line
#                          (pass, elapsed, estimated time left): it runs on a pseudo-terminal so
#                          that it prints one.
#     --json FILE          where to write the results (default bench/results/scale.json; the
#                          table goes to FILE with .md for .json)
#     --keep DIR           keep each bake's output (renders, report) in DIR/<kind>-<count>
#     --note TEXT          recorded in the JSON and the table's heading (e.g. which code was measured)
set -euo pipefail
cd "$(dirname "$0")/.."

build=build/release
kinds=city,furniture,foliage
counts=10k,100k,1M,3M
quality=default
large_quality=draft
large_from=1000000
timeout=3600
json=bench/results/scale.json
keep=
note=
while (($#)); do
    case $1 in
        --build) build=$2; shift 2 ;;
        --kinds) kinds=$2; shift 2 ;;
        --counts) counts=$2; shift 2 ;;
        --quality) quality=$2; shift 2 ;;
        --large-quality) large_quality=$2; shift 2 ;;
        --large-from) large_from=$2; shift 2 ;;
        --timeout) timeout=$2; shift 2 ;;
        --json) json=$2; shift 2 ;;
        --keep) keep=$2; shift 2 ;;
        --note) note=$2; shift 2 ;;
        --) shift; break ;;
        -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d'; exit 0 ;;
        *) echo "scale.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
    esac
done
exe=$build/hemirad
[[ -x $exe ]] || { echo "scale.sh: no $exe (build first)" >&2; exit 2; }

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# The runner and the report in Python: wait4 gives the bake's own peak RSS and CPU time without
# depending on GNU time, and a pseudo-terminal makes the bake print its progress line.
python3 - "$exe" "$kinds" "$counts" "$quality" "$large_quality" "$large_from" "$timeout" "$json" "$work" \
    "$keep" "$note" "$@" <<'PY'
import datetime, json, os, pty, re, select, shutil, signal, subprocess, sys, time

exe, kinds, counts, quality, large_quality, large_from, timeout, out_json, work, keep, note = sys.argv[1:12]
extra = sys.argv[12:]
large_from, timeout = int(large_from), float(timeout)

def count_of(text):
    m = re.fullmatch(r"(\d+(?:\.\d+)?)([kKmM]?)", text)
    if not m:
        sys.exit(f"scale.sh: bad count {text}")
    return int(round(float(m.group(1)) * {"": 1, "k": 1e3, "K": 1e3, "m": 1e6, "M": 1e6}[m.group(2)]))

def bake(args, limit):
    """Runs a bake with stderr on a pseudo-terminal; returns status, rusage, seconds, last progress line."""
    master, slave = pty.openpty()
    start = time.monotonic()
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=slave, stdin=subprocess.DEVNULL)
    os.close(slave)
    tail, status, stop_sent = b"", None, None
    while True:
        now = time.monotonic()
        if stop_sent is None and now - start > limit:
            proc.send_signal(signal.SIGTERM)  # the bake cleans up and exits 130
            stop_sent = now
        elif stop_sent is not None and now - stop_sent > 30:
            proc.kill()
        ready, _, _ = select.select([master], [], [], 1.0)
        if ready:
            try:
                chunk = os.read(master, 65536)
            except OSError:
                chunk = b""
            tail = (tail + chunk)[-8192:]
        pid, wait_status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            break
    wall = time.monotonic() - start
    os.close(master)
    proc.returncode = os.waitstatus_to_exitcode(wait_status)
    lines = [l.strip() for l in re.split(rb"[\r\n]+", tail) if l.strip()]
    # Without the terminal's escapes (the progress line clears itself with ESC [K).
    text = [re.sub(r"\x1b\[[0-9;]*[A-Za-z]", "", l.decode(errors="replace")) for l in lines]
    progress = next((l for l in reversed(text) if "pass" in l or "row" in l), "")
    if stop_sent is not None:
        status = "timeout"
    elif proc.returncode == 0:
        status = "ok"
    else:
        status = f"exit {proc.returncode}"
    return status, usage, wall, progress, text[-3:]

def machine():
    cpu = next((l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name")), "?")
    devices = subprocess.run([exe, "devices"], capture_output=True, text=True).stdout.splitlines()
    return {"cpu": cpu, "hardware_threads": os.cpu_count(), "device": " ".join(devices[1].split()) if len(devices) > 1 else ""}

try:
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
except OSError:
    commit = ""
result = {"note": note, "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
          "commit": commit, "machine": machine(), "timeout_s": timeout, "bake_options": extra, "runs": []}

def write_results():
    os.makedirs(os.path.dirname(out_json) or ".", exist_ok=True)
    with open(out_json, "w") as f:
        json.dump(result, f, indent=1)
        f.write("\n")
    with open(re.sub(r"\.json$", "", out_json) + ".md", "w") as f:
        f.write(table())

def fmt_bytes(b):
    return f"{b / 2**30:.2f} GiB" if b >= 2**30 else f"{b / 2**20:.0f} MiB"

def table():
    m = result["machine"]
    rows = [f"Scale benchmark{': ' + note if note else ''} ({m['hardware_threads']} hardware threads of {m['cpu']}; {m['device']}; "
            f"commit {result['commit']}, {result['date']})", "",
            "| scene | triangles | quality | patches / elements | solver, passes | status | wall | CPU | peak RSS | bytes / element | load before, after |",
            "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in result["runs"]:
        elements = r.get("elements")
        pe = f"{r['patches']} / {elements}" if elements else "–"
        passes = f"{r['solver']}, {r['passes']}" if r.get("passes") is not None else "–"
        status = r["status"] + (f" ({r['progress']})" if r["status"] == "timeout" and r.get("progress") else "")
        if r["status"] == "ok" and r.get("converged") is False:  # stopped at --max-passes, not at the threshold
            status += ", not converged" + (f" (error {r['error']:.2g})" if r.get("error") is not None else "")
        per = f"{r['peak_rss_bytes'] / elements:,.0f}" if elements else "–"
        load = f"{r['load_before']:.1f}, {r['load_after']:.1f}"
        rows.append(f"| {r['kind']}:{r['count']} | {r['triangles']:,} | {r['quality']} | {pe} | {passes} | {status} | "
                    f"{r['wall_s']:.1f} s | {r['cpu_s']:.1f} s | {fmt_bytes(r['peak_rss_bytes'])} | {per} | {load} |")
    return "\n".join(rows) + "\n"

for kind in kinds.split(","):
    for count in counts.split(","):
        n = count_of(count)
        q = large_quality if n >= large_from else quality
        glb = os.path.join(work, f"{kind}-{count}.glb")
        t0 = time.monotonic()
        wrote = subprocess.run([exe, "scene", "write", f"{kind}:{count}", glb], capture_output=True, text=True, check=True)
        write_s = time.monotonic() - t0
        triangles = int(re.search(r": (\d+) triangles", wrote.stdout).group(1))
        out = os.path.join(keep, f"{kind}-{count}") if keep else os.path.join(work, "out")
        shutil.rmtree(out, ignore_errors=True)
        print(f"scale.sh: {kind}:{count} ({triangles} triangles), {q}, at most {timeout:.0f} s ...", file=sys.stderr, flush=True)
        load_before = float(open("/proc/loadavg").read().split()[0])
        status, usage, wall, progress, last = bake([exe, "bake", glb, "-o", out, "--quality", q, *extra], timeout)
        run = {"kind": kind, "count": count, "requested": n, "triangles": triangles, "quality": q, "status": status,
               "wall_s": round(wall, 2), "cpu_s": round(usage.ru_utime + usage.ru_stime, 2),
               "peak_rss_bytes": usage.ru_maxrss * 1024, "write_s": round(write_s, 2),
               "glb_bytes": os.path.getsize(glb),
               # The 1-minute load average before and after: wall times on a shared machine mean
               # little without it (CPU time is less affected).
               "load_before": load_before, "load_after": float(open("/proc/loadavg").read().split()[0])}
        if progress:
            run["progress"] = progress
        if status != "ok" and status != "timeout":
            run["stderr"] = last
        report_file = os.path.join(out, "report.json")
        if status == "ok" and os.path.exists(report_file):
            rep = json.load(open(report_file))
            c = rep["counts"]
            run.update({"patches": c["patches"], "elements": c["elements"],
                        "elements_before_refinement": c["elements_before_refinement"], "passes": rep["passes"],
                        "solver": rep["settings"]["solver"], "converged": rep["converged"], "error": rep.get("error"),
                        "device": rep["device"]["name"] or rep["device"]["backend"],
                        "memory_estimate_bytes": rep["plan"]["memory"]["estimate"],
                        # Where the time and the planned memory go: what the engine work needs to see.
                        "memory_parts_bytes": rep["plan"]["memory"]["parts"], "timings_s": rep.get("timings_s")})
        result["runs"].append(run)
        write_results()  # after every bake, so a long run that is cut short keeps what it measured
        print(table().splitlines()[-1], flush=True)
        os.remove(glb)

print(table(), end="")
PY
