#!/usr/bin/env python3
"""Predicts how a bake scales over many GPUs (one MPI rank each) from what `hemirad bench --scaling`
measured on one machine: a shot's compute, rank 0's serial work per shot, and the bytes a shot's
request and row take on the wire.

    python3 bench/scaling_model.py bench/results/scaling.json [--gpu-speedup 100] [--png out.png]

The model (one batch of K = 16 P shots on P ranks, rank 0 among them):

  compute   each rank computes K / P shots of t_gpu seconds; the guided chunks end with single
            shots, so the last rank finishes at most one shot after the others:
                T_compute = (K / P + 1) t_gpu
  network   every worker's rows go to rank 0 through its one link of bandwidth W (100 Gb/s), in
            chunks: rank 0 receives K (P - 1) / P rows of r bytes, and each chunk pays a latency
            a (MPI over the network, ~5 us) and rank 0's poll (hemirad polls every 100 us near the
            expected end of a chunk: 50 us on average); the rows of a chunk overlap the other ranks'
            compute, so what adds is the larger of compute and transfer:
                T_network = K (P - 1) / P * r / W,   T_latency = (a + poll) * chunks / P
  host      rank 0 unpacks every worker row (u seconds a row) and applies every shot to the solve
            (h seconds a pass, progressive; the matrix solver stores rows, u only): serial, while the
            ranks wait for the next batch:
                T_host = K (u + h)
  batch     T(P) = max(T_compute, T_network) + T_latency + T_host
  efficiency  E(P) = (K / T(P)) / (P / (t_gpu + h))   (one rank: no network, no unpacking)

t_gpu is a GPU's time per shot: none was measured (no GPU was lent to this project), so it is the
measured CPU shot time (one PoCL thread) divided by an assumed GPU speed-up (--gpu-speedup,
default 100: an H100 against one core of the 2-core machine here, a guess this script states as
one). Everything else is measured. Sending the mesh once to every rank (P - 1 copies from rank 0)
is a start-up cost, reported apart.
"""
import argparse
import json
import math
import sys

NETWORK_BYTES_PER_S = 100e9 / 8  # 100 Gb/s
LATENCY_S = 5e-6                 # one MPI message over the network
POLL_S = 50e-6                   # rank 0's average wait past a chunk's end (kPollClose / 2)
GPUS = [1, 2, 4, 8, 16, 32, 64, 128, 256, 512]


def chunks_per_batch(k, p):
    """Chunks of guided scheduling: each take is 1 / (2 P) of what is left, at least one shot."""
    left, n = k, 0
    while left > 0:
        take = max(1, math.ceil(left / (2 * p))) if p > 1 else left
        left -= take
        n += 1
    return n


def predict(inputs, gpu_speedup, solver):
    t_gpu = inputs["shot_seconds"] / gpu_speedup
    h = inputs["host_seconds_per_pass"] if solver == "progressive" else 0.0
    u = inputs["row_unpack_seconds_per_shot"]
    r = inputs["row_bytes_per_shot"] + inputs["request_bytes_per_shot"]
    per_member = inputs["batch_per_member"]
    rows = []
    for p in GPUS:
        k = per_member * p
        compute = (k / p + (1 if p > 1 else 0)) * t_gpu
        network = k * (p - 1) / p * r / NETWORK_BYTES_PER_S
        latency = (LATENCY_S + POLL_S) * chunks_per_batch(k, p) / p if p > 1 else 0.0
        host = k * ((u if p > 1 else 0.0) + h)
        batch = max(compute, network) + latency + host
        rate = k / batch
        one = 1.0 / (t_gpu + h)
        bound = max(("compute", compute), ("network", network), ("host", host), key=lambda x: x[1])[0]
        rows.append({"gpus": p, "batch": k, "shots_per_s": rate, "efficiency": rate / (p * one),
                     "bound": bound, "compute_s": compute, "network_s": network, "latency_s": latency, "host_s": host,
                     "mesh_broadcast_s": (p - 1) * inputs["mesh_bytes"] / NETWORK_BYTES_PER_S})
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("scaling_json", help="the JSON of hemirad bench --scaling")
    parser.add_argument("--gpu-speedup", type=float, default=100.0,
                        help="a GPU's shot rate over the measured one (one PoCL thread); an assumption")
    parser.add_argument("--png", help="also plot predicted efficiency against GPUs here")
    args = parser.parse_args()
    doc = json.load(open(args.scaling_json))
    inputs = doc["model_inputs"]
    s = doc["settings"]
    print(f"measured on {doc['machine'].get('cpu', '?')}: {s['scene']} ({s['triangles']} triangles, N {s['hemicube']})")
    print(f"  shot {1e3 * inputs['shot_seconds']:.2f} ms (one member), host {1e3 * inputs['host_seconds_per_pass']:.3f} ms"
          f" a progressive pass, unpack {1e6 * inputs['row_unpack_seconds_per_shot']:.1f} us a row,"
          f" row {inputs['row_bytes_per_shot'] / 1e3:.1f} kB, mesh {inputs['mesh_bytes'] / 1e6:.1f} MB")
    print(f"  assumed: a GPU shoots {args.gpu_speedup:g}x as fast; 100 Gb/s, {LATENCY_S * 1e6:g} us a message\n")
    results = {}
    for solver in ("progressive", "matrix"):
        rows = predict(inputs, args.gpu_speedup, solver)
        results[solver] = rows
        print(f"{solver} ({'rank 0 applies every pass' if solver == 'progressive' else 'rows stored, solved after'}):")
        print("| GPUs | shots/s | efficiency | bound by | mesh to all ranks (s) |")
        print("|---:|---:|---:|:---|---:|")
        for r in rows:
            if r["gpus"] in (1, 8, 64, 512) or r["gpus"] == GPUS[-1]:
                print(f"| {r['gpus']} | {r['shots_per_s']:.3g} | {100 * r['efficiency']:.0f}% | {r['bound']} |"
                      f" {r['mesh_broadcast_s']:.2f} |")
        stop = next((r["gpus"] for r in rows if r["efficiency"] < 0.5), None)
        print(f"efficiency falls below 50% at {stop} GPUs\n" if stop else "efficiency stays above 50% to 512 GPUs\n")
    if args.png:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(7, 4.2))
        for solver, style in (("progressive", "o-"), ("matrix", "s-")):
            for speedup, alpha in ((args.gpu_speedup / 3, 0.45), (args.gpu_speedup, 1.0), (args.gpu_speedup * 3, 0.45)):
                rows = predict(inputs, speedup, solver)
                ax.plot([r["gpus"] for r in rows], [100 * r["efficiency"] for r in rows], style, alpha=alpha,
                        label=f"{solver}, GPU {speedup:.0f}x one core")
        measured = [r for r in doc["runs"] if r["devices"] == 1]
        ax.plot([r["ranks"] for r in measured], [100 * r["efficiency"] for r in measured], "k*", markersize=12,
                label="measured (CPU ranks, this machine)")
        ax.set_xscale("log", base=2)
        ax.set_xlabel("GPUs (one MPI rank each), 100 Gb/s network")
        ax.set_ylabel("parallel efficiency (%)")
        ax.set_ylim(0, 105)
        ax.set_title(f"Predicted efficiency, {s['scene']} at N {s['hemicube']}")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(args.png, dpi=110)
        print(f"wrote {args.png}")
    return results


if __name__ == "__main__":
    main()
    sys.exit(0)
