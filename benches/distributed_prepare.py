#!/usr/bin/env python3
"""Times a task-graph job's prepare on a local cluster: prepared by byte ranges over the workers,
and read whole in the `start` task (`--range-mib 0`), on the same input, one after the other.

    python3 benches/distributed_prepare.py [--points 4000000] [--workers 3] [--range-mib 16]
        [--bin target/release/rbfsurf] [--full REPORT.json]

Starts its own `nats-server -js` on a free loopback port with a temporary store, one API node
(`serve --nats`) and K workers (`--concurrency 1`), generates a torus with normals (binary PLY),
submits it with default parameters and a memory budget that sends it to the task graph, and
reads the workers' logs: every task's worker, start and seconds. Prepare is measured from the
`start` task's beginning to the first `block` task's; then the job is cancelled. With `--full
REPORT.json` only the range run is made, the job runs to its end and its report (with `tasks[]`
and `critical_path`) is saved there, for `benches/distributed_projection.py`. Prints, per run,
the prepare time, the longest prepare task and the busy seconds per worker.
"""

import argparse
import datetime as dt
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for(what, cond, timeout=600):
    t = time.time()
    while not cond():
        if time.time() - t > timeout:
            sys.exit(f"timed out waiting for {what}")
        time.sleep(0.2)


LINE = re.compile(r"^(\S+)\s.*?(task started|task finished).*?job=(\S+) task=(.+?) (?:delivery|seconds)=")


def events(log_text):
    """(timestamp, kind, task, seconds or None, worker) per task line of a worker log."""
    out = []
    for line in log_text.splitlines():
        m = LINE.search(line)
        if not m:
            continue
        ts = dt.datetime.fromisoformat(m.group(1).replace("Z", "+00:00")).timestamp()
        secs = re.search(r"seconds=([0-9.e+-]+)", line)
        out.append((ts, m.group(2), m.group(4), float(secs.group(1)) if secs else None))
    return out


def run(args, tmp, range_mib):
    port = free_port()
    store = os.path.join(tmp, f"js-{range_mib}")
    nats = subprocess.Popen(["nats-server", "-js", "-a", "127.0.0.1", "-p", str(port), "-sd", store],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    url = f"nats://127.0.0.1:{port}"
    procs, logs = [nats], []
    env = dict(os.environ, RUST_LOG="info")
    try:
        time.sleep(1.0)
        for k in range(args.workers):
            log = os.path.join(tmp, f"w{k}-{range_mib}.log")
            logs.append(log)
            procs.append(subprocess.Popen(
                [args.bin, "worker", "--nats", url, "--concurrency", "1", "--range-mib", str(range_mib)],
                stdout=open(log, "w"), stderr=subprocess.STDOUT, env=env))
        api_port = free_port()
        api_log = os.path.join(tmp, f"api-{range_mib}.log")
        procs.append(subprocess.Popen(
            [args.bin, "serve", "--nats", url, "--addr", f"127.0.0.1:{api_port}",
             "--data-dir", os.path.join(tmp, f"api-{range_mib}"), "--max-upload-mib", "4096"],
            stdout=open(api_log, "w"), stderr=subprocess.STDOUT, env=env))
        base = f"http://127.0.0.1:{api_port}"
        wait_for("the API node", lambda: "listening" in open(api_log).read(), 60)
        wait_for("the workers", lambda: all("waiting for tasks" in open(l).read() for l in logs), 60)
        with open(args.cloud, "rb") as f:
            body = f.read()
        q = f"max-memory-mib={args.budget_mib}"
        req = urllib.request.Request(f"{base}/v1/reconstructions?{q}", data=body,
                                     headers={"Content-Type": "application/ply"})
        t0 = time.time()
        job = json.load(urllib.request.urlopen(req, timeout=600))
        jid = job["id"]
        text = lambda: "".join(open(l).read() for l in logs)
        if args.full:
            wait_for("the job", lambda: json.load(urllib.request.urlopen(f"{base}/v1/reconstructions/{jid}"))["status"]
                     in ("succeeded", "failed"), 7200)
        else:
            wait_for("the block phase", lambda: f"job={jid} task=block" in text(), 3600)
            urllib.request.urlopen(urllib.request.Request(f"{base}/v1/reconstructions/{jid}", method="DELETE"))
            time.sleep(2.0)
        view = None
        if args.full:
            view = json.load(urllib.request.urlopen(f"{base}/v1/reconstructions/{jid}"))
            rep = urllib.request.urlopen(f"{base}/v1/reconstructions/{jid}/report").read()
            with open(args.full, "wb") as f:
                f.write(rep)
        per_worker = {}
        start = first_block = None
        longest = ("", 0.0)
        for k, log in enumerate(logs):
            for ts, kind, task, secs in events(open(log).read()):
                if kind == "task started" and task == "start":
                    start = ts if start is None else min(start, ts)
                if kind == "task started" and task.startswith("block "):
                    first_block = ts if first_block is None else min(first_block, ts)
                if kind == "task finished" and not task.startswith(("block", "region", "merge")):
                    per_worker.setdefault(f"w{k}", []).append((task, secs))
                    if secs > longest[1]:
                        longest = (task, secs)
        print(f"\n## range-mib {range_mib}: {args.points} points, {len(body) / 2**20:.1f} MiB, {args.workers} workers")
        print(f"job {jid}: upload answered after {time.time() - t0:.1f} s")
        print(f"prepare (start task begins -> first block task begins): {first_block - start:.2f} s")
        print(f"longest prepare task: {longest[0]} {longest[1]:.3f} s")
        for w, tasks in sorted(per_worker.items()):
            kinds = {}
            for task, secs in tasks:
                key = re.sub(r" \d+.*$", "", task)
                n, s = kinds.get(key, (0, 0.0))
                kinds[key] = (n + 1, s + secs)
            desc = ", ".join(f"{n} {k} ({s:.2f} s)" for k, (n, s) in sorted(kinds.items()))
            print(f"{w}: busy {sum(s for _, s in tasks):.2f} s in prepare tasks: {desc}")
        if view:
            print(f"job {view['status']}")
    finally:
        for p in procs[::-1]:
            p.terminate()
        for p in procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--points", type=int, default=4_000_000)
    ap.add_argument("--workers", type=int, default=3)
    ap.add_argument("--range-mib", type=float, default=16)
    ap.add_argument("--budget-mib", type=int, default=2048)
    ap.add_argument("--bin", default="target/release/rbfsurf")
    ap.add_argument("--full", metavar="REPORT.json")
    args = ap.parse_args()
    if not shutil.which("nats-server"):
        sys.exit("nats-server is not installed (apt-get install nats-server)")
    tmp = tempfile.mkdtemp(prefix="rbfsurf-prepare-")
    args.cloud = os.path.join(tmp, "torus.ply")
    subprocess.run([args.bin, "generate", "torus", "--points", str(args.points), "-o", args.cloud],
                   check=True, stdout=subprocess.DEVNULL)
    try:
        for mib in (args.range_mib,) if args.full else (args.range_mib, 0):
            run(args, tmp, mib)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
