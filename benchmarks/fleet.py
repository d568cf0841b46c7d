#!/usr/bin/env python
"""Fleet benchmarks: throughput of ``fricli fleet``, the engine's per-job overhead, wear detection.

    python benchmarks/fleet.py throughput [--robots 40]   jobs/minute with 1 and 2 local workers
                                                          (whole command, identify, 40 x 6 x 1)
    python benchmarks/fleet.py overhead [--jobs 12]       Dask's cost per job next to a default adapt job
    python benchmarks/fleet.py wear [--seeds 5]           30-day fleets with known wearing joints:
                                                          what ``trend`` flags (defaults of fricli trend)

Each prints a table on stderr and JSON on stdout. The fleets are simulated under --work
(default a temporary folder).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)
ENV = {**os.environ, "PYTHONPATH": ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")}


def fricli(*args, cwd=None) -> float:
    """Run ``python -m fricli ARGS``; returns the wall time [s]."""
    start = time.perf_counter()
    res = subprocess.run([sys.executable, "-m", "fricli", *map(str, args)], cwd=cwd, env=ENV,
                         capture_output=True, text=True)
    if res.returncode not in (0, 12):
        sys.exit(f"fricli {' '.join(map(str, args))} failed ({res.returncode}): {res.stderr[-500:]}")
    return time.perf_counter() - start


def throughput(work: str, robots: int) -> dict:
    folder = os.path.join(work, f"fleet-{robots}x6x1")
    sim = fricli("simulate", "--fleet", f"{robots}x6x1", "--seed", 0, "-o", folder, "-q")
    jobs = robots * 6
    out = {"jobs": jobs, "simulate_s": sim, "cpus": os.cpu_count(), "load_before": os.getloadavg()[0]}
    for workers in (1, 2):
        wall = fricli("fleet", os.path.join(folder, "fleet.toml"), "--workers", workers, "--force", "-q")
        out[f"workers_{workers}"] = {"wall_s": wall, "jobs_per_min": jobs / wall * 60}
    out["unchanged_run_s"] = fricli("fleet", os.path.join(folder, "fleet.toml"), "-q")
    out["load_after"] = os.getloadavg()[0]
    print(f"{jobs} identify jobs ({robots} robots x 6 joints x 1 day), simulated in {sim:.1f} s", file=sys.stderr)
    for w in (1, 2):
        r = out[f"workers_{w}"]
        print(f"  {w} worker(s): {r['wall_s']:.1f} s, {r['jobs_per_min']:.0f} jobs/min", file=sys.stderr)
    print(f"  second run (every job unchanged): {out['unchanged_run_s']:.1f} s", file=sys.stderr)
    return out


def overhead(work: str, n: int) -> dict:
    import dataclasses

    from fricli.fleet import manifest, pipelines, run

    folder = os.path.join(work, "fleet-overhead")
    fricli("simulate", "--fleet", f"{max(1, n // 6)}x6x1", "--seed", 1, "-o", folder, "-q")
    base_jobs = manifest.load(os.path.join(folder, "fleet.toml")).jobs[:n]
    bases = [pipelines.run(j) for j in base_jobs]          # LuGre bases, identified in this process
    assert all(b["status"] in ("ok", "unchanged") for b in bases), bases
    jobs = [dataclasses.replace(j, pipeline="adapt", base=j.model, model=j.model.replace(".npz", "-adapted.npz"))
            for j in base_jobs]
    start = time.perf_counter()
    with run.client(workers=1) as c:
        started = time.perf_counter() - start
        c.submit(pipelines.run, jobs[0], if_changed=False, pure=False).result()   # imports on the worker
        t0 = time.perf_counter()
        results = c.gather(c.map(pipelines.run, jobs, if_changed=False, pure=False))
        wall = time.perf_counter() - t0
    assert all(r["status"] == "ok" for r in results), [r["reason"] for r in results]
    work_s = sum(r["seconds"] for r in results)
    per_job = (wall - work_s) / len(jobs)
    mean_job = work_s / len(jobs)
    out = {"jobs": len(jobs), "cluster_start_s": started, "wall_s": wall, "job_s_mean": mean_job,
           "overhead_per_job_s": per_job, "overhead_share": per_job / mean_job}
    print(f"{len(jobs)} default adapt jobs on 1 worker: {mean_job:.2f} s each; engine overhead "
          f"{1000 * per_job:.1f} ms per job ({100 * per_job / mean_job:.2f} %); local cluster start "
          f"{started:.1f} s once per run", file=sys.stderr)
    return out


def wear(work: str, seeds: int, robots: int, days: int, wearing: int) -> dict:
    import concurrent.futures

    from fricli.fleet import history, manifest, run, trend
    from fricli.sim import fleet

    rows = []
    for seed in range(seeds):
        folder = os.path.join(work, f"wear-{seed}")
        with concurrent.futures.ProcessPoolExecutor() as pool:
            joints = fleet.simulate_fleet(folder, robots=robots, joints_per_robot=6, days=days, wearing=wearing,
                                          seed=seed, map_fn=lambda f, t: pool.map(f, t, chunksize=8))
        outcome = run.run(manifest.load(os.path.join(folder, "fleet.toml")))
        result = trend.trends(history.read(os.path.join(folder, "history")))
        truth = {(j.robot, str(j.number)) for j in joints if j.wears}
        flagged = {(t.robot, t.joint) for t in result if t.flagged}
        rows.append({"seed": seed, "joints": len(result), "wearing": len(truth), "failed_jobs": outcome.count("failed"),
                     "hits": len(truth & flagged), "misses": len(truth - flagged),
                     "false_alarms": len(flagged - truth),
                     "worst_healthy_level": max(max(t.level.values(), default=0) for t in result
                                                if (t.robot, t.joint) not in truth),
                     "worst_healthy_growth": max(max(t.growth.values(), default=0) for t in result
                                                 if (t.robot, t.joint) not in truth),
                     "weakest_wear_level": min(max(t.level.values()) for t in result
                                               if (t.robot, t.joint) in truth)})
        print(json.dumps(rows[-1]), file=sys.stderr)
    healthy = sum(r["joints"] - r["wearing"] for r in rows)
    out = {"robots": robots, "days": days, "rule": vars(trend.WearRule()), "seeds": rows,
           "false_alarm_rate": sum(r["false_alarms"] for r in rows) / healthy,
           "miss_rate": sum(r["misses"] for r in rows) / sum(r["wearing"] for r in rows)}
    print(f"{seeds} seeds x {robots} robots x 6 joints x {days} days, {wearing} wearing each: "
          f"false alarms {sum(r['false_alarms'] for r in rows)} of {healthy} healthy joints, "
          f"misses {sum(r['misses'] for r in rows)} of {sum(r['wearing'] for r in rows)}", file=sys.stderr)
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("what", choices=("throughput", "overhead", "wear"))
    p.add_argument("--work", default=None, help="Folder for the simulated fleets [default: a temporary one].")
    p.add_argument("--robots", type=int, default=None)
    p.add_argument("--jobs", type=int, default=12)
    p.add_argument("--seeds", type=int, default=5)
    p.add_argument("--days", type=int, default=30)
    p.add_argument("--wearing", type=int, default=3)
    a = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = a.work or tmp
        os.makedirs(work, exist_ok=True)
        if a.what == "throughput":
            out = throughput(work, a.robots or 40)
        elif a.what == "overhead":
            out = overhead(work, a.jobs)
        else:
            out = wear(work, a.seeds, a.robots or 2, a.days, a.wearing)
    print(json.dumps(out, indent=1, default=str))


if __name__ == "__main__":
    main()
