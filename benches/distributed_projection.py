#!/usr/bin/env python3
"""Projects a distributed job's measured task times to 10^8 and 10^9 points on K nodes.

    python3 benches/distributed_projection.py REPORT.json [--slots-per-node S] [--nodes 3,16,65]

REPORT.json is the report of a task-graph job run by `rbfsurf serve --nats` workers (it has
`tasks[]`, `blocks[]`, `input.used`). The model, from the measured tasks:

* prepare, when the report's prepare ran over the workers by byte ranges (it has `clean-up <k>`
  tasks): each phase (survey, sample, route range tasks, clean-up tasks) is work that grows with
  N spread over K * S slots plus its slowest task; the steps between the phases (number ranges,
  plan blocks, estimates, complete plan) read bounded values and are taken as measured.
  Otherwise prepare is one task that streams the whole input, so its time grows with the input:
  t_prepare(N) = (measured prepare seconds / measured points) * N, and a prepare split over
  byte ranges would divide this by the nodes; both columns are given.
* blocks: the plan's block size depends on the memory budget only, so the number of blocks grows
  with N and each costs what the measured ones cost. Work = (sum of block seconds / points) * N,
  spread over K * S slots, plus one slowest block (the last one to start):
  t_blocks = work / (K * S) + max block seconds.
* regions: likewise (their number grows with the surface's area, taken as growing with N,
  which is an upper bound for a denser sampling of the same surface).
* merge: one task over the welded mesh, taken as growing with N (an upper bound: with a capped
  grid resolution the mesh stops growing).
* per-node memory: each slot holds at most one block or region task, whose peak is bounded by
  the job's memory budget whatever N is (blocks[].peak_rss_mib measured): S * that peak.

The result is compared with the figure published for Distributed Poisson surface
reconstruction: 10^9 points in under 20 minutes on 65 nodes, at most 45 GB per node.
"""

import argparse
import json
import sys


def phase(tasks, prefix):
    return [t for t in tasks if t["task"] == prefix or t["task"].startswith(prefix + " ")]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("report")
    ap.add_argument("--slots-per-node", type=int, default=1,
                    help="worker tasks run at once on one node (default 1)")
    ap.add_argument("--nodes", default="3,16,65")
    ap.add_argument("--points", default="1e8,1e9")
    a = ap.parse_args()
    rep = json.load(open(a.report))
    tasks = rep.get("tasks")
    if not tasks:
        sys.exit(f"{a.report}: no tasks[] (not a task-graph job of the NATS executor)")
    n = rep["input"]["used"]
    prep = sum(t["seconds"] for t in phase(tasks, "prepare"))
    blocks = [t["seconds"] for t in phase(tasks, "block")]
    regions = [t["seconds"] for t in phase(tasks, "region")]
    merge = sum(t["seconds"] for t in phase(tasks, "merge"))
    peak = max(b["peak_rss_mib"] for b in rep["blocks"])
    cp = rep.get("critical_path", {})
    print(f"measured: {n:,} points, {len(blocks)} blocks, {len(regions)} regions, "
          f"workers {sorted({t['worker'] for t in tasks})}")
    print(f"  prepare {prep:.1f} s ({prep / n * 1e6:.2f} us/point), blocks sum {sum(blocks):.1f} s "
          f"(max {max(blocks):.1f} s, {sum(blocks) / n * 1e6:.2f} us/point), regions sum "
          f"{sum(regions):.1f} s (max {max(regions):.1f} s), merge {merge:.1f} s; "
          f"critical path {cp.get('seconds', 0):.1f} s of {cp.get('wall_seconds', 0):.1f} s wall; "
          f"block peak RSS {peak:.0f} MiB")
    print()
    print("| points | nodes | prepare | blocks | regions | merge | total, one prepare "
          "| total, prepare split | memory per node |")
    print("|---|---|---|---|---|---|---|---|---|")
    s = a.slots_per_node
    spread = any(t["task"].startswith("clean-up ") for t in tasks)
    passes = [[t["seconds"] for t in phase(tasks, p)]
              for p in ("survey range", "sample range", "route range", "clean-up")]
    between = sum(t["seconds"] for p in ("number ranges", "plan blocks", "estimates", "complete plan")
                  for t in phase(tasks, p))
    if spread:
        print(f"prepare over the workers: pass tasks {[len(p) for p in passes]}, sums "
              f"{[round(sum(p), 2) for p in passes]} s, slowest {[round(max(p), 2) for p in passes]} s, "
              f"steps between {between:.2f} s")
    for pts in (float(x) for x in a.points.split(",")):
        scale = pts / n
        for k in (int(x) for x in a.nodes.split(",")):
            if spread:
                t_prep = between + sum(sum(p) * scale / (k * s) + max(p) for p in passes)
                t_split = t_prep
            else:
                t_prep = prep * scale
                t_split = t_prep / k
            t_blocks = sum(blocks) * scale / (k * s) + max(blocks)
            t_regions = sum(regions) * scale / (k * s) + max(regions)
            t_merge = merge * scale
            one = t_prep + t_blocks + t_regions + t_merge
            split = t_split + t_blocks + t_regions + t_merge
            print(f"| {pts:.0e} | {k} | {t_prep / 60:.1f} min | {t_blocks / 60:.1f} min | "
                  f"{t_regions / 60:.1f} min | {t_merge / 60:.1f} min | {one / 60:.1f} min | "
                  f"{split / 60:.1f} min | {s * peak / 1024:.1f} GiB |")
    print()
    print("Distributed Poisson (published): 1e9 points < 20 min on 65 nodes, <= 45 GB per node.")


if __name__ == "__main__":
    main()
