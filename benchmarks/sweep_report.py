"""Time report of a finished sweep from Snakemake's benchmark files. Asserts nothing.

    python benchmarks/sweep_report.py                 # results/benchmarks of this checkout
    python benchmarks/sweep_report.py path/to/results/benchmarks --top 15

Prints the jobs' summed wall and CPU time, the span from the first job's
start to the last job's end (from file times: each benchmark file is written
when its job ends), the CPU time per layout and N, and the slowest jobs.
A job whose CPU time is well below its wall time shared its core with
something else (another program, oversubscribed threads): such a run does
not measure the solver, so they are counted and flagged.
"""

from __future__ import annotations

import argparse
import csv
import re
from collections import defaultdict
from pathlib import Path

#: Below this CPU / wall ratio a single-threaded job was starved of its core.
STARVED = 0.9


def read_jobs(root: Path) -> list[dict]:
    """One record per benchmark file: name, wall s, CPU s, end time (file mtime)."""
    jobs = []
    for path in sorted(root.rglob("*.tsv")):
        with open(path, newline="") as fh:
            rows = list(csv.DictReader(fh, delimiter="\t"))
        if not rows:
            continue
        row = rows[-1]  # --benchmark-repeats would give several rows
        cpu = row.get("cpu_time", "NA")
        jobs.append({"name": str(path.relative_to(root).with_suffix("")),
                     "wall": float(row["s"]),
                     "cpu": float(cpu) if cpu not in ("", "NA") else float("nan"),
                     "rss_mb": float(row.get("max_rss", "nan") or "nan"),
                     "end": path.stat().st_mtime})
    return jobs


def group_of(name: str) -> str:
    """'simulate/random/N1620_kbar0.1_seed0' -> 'simulate/random/N1620'."""
    return re.sub(r"_kbar.*$", "", name)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("root", nargs="?", default="results/benchmarks", type=Path)
    parser.add_argument("--top", type=int, default=10, help="slowest jobs to list")
    args = parser.parse_args()
    jobs = read_jobs(args.root)
    if not jobs:
        raise SystemExit(f"no benchmark files under {args.root}")
    wall = sum(j["wall"] for j in jobs)
    cpu = sum(j["cpu"] for j in jobs)
    span = max(j["end"] for j in jobs) - min(j["end"] - j["wall"] for j in jobs)
    starved = [j for j in jobs if j["wall"] > 5 and j["cpu"] < STARVED * j["wall"]]
    print(f"{len(jobs)} jobs; span {span:.0f} s ({span / 60:.1f} min); "
          f"summed wall {wall:.0f} s, summed CPU {cpu:.0f} s; "
          f"peak RSS {max(j['rss_mb'] for j in jobs):.0f} MB")
    print(f"jobs with CPU < {STARVED:.0%} of wall (core shared with something else): "
          f"{len(starved)}")
    groups: dict[str, list[float]] = defaultdict(lambda: [0, 0.0, 0.0])
    for j in jobs:
        g = groups[group_of(j["name"])]
        g[0] += 1
        g[1] += j["wall"]
        g[2] += j["cpu"]
    print(f"\n{'group':<28} {'jobs':>5} {'wall s':>8} {'CPU s':>8} {'CPU %':>6}")
    for name, (count, w, c) in sorted(groups.items(), key=lambda kv: -kv[1][2]):
        print(f"{name:<28} {count:>5} {w:>8.0f} {c:>8.0f} {100 * c / cpu:>6.1f}")
    print(f"\n{'slowest jobs':<42} {'wall s':>8} {'CPU s':>8} {'RSS MB':>7}")
    for j in sorted(jobs, key=lambda j: -j["wall"])[: args.top]:
        print(f"{j['name']:<42} {j['wall']:>8.1f} {j['cpu']:>8.1f} {j['rss_mb']:>7.0f}")


if __name__ == "__main__":
    main()
