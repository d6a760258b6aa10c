"""Time report of a finished sweep from Snakemake's benchmark files. Asserts nothing.

    python benchmarks/sweep_report.py                 # results/benchmarks of this checkout
    python benchmarks/sweep_report.py path/to/results/benchmarks --top 15

Prints the jobs' summed wall time, the span from the first job's start to
the last job's end (from file times: each benchmark file is written when its
job ends), the wall time per layout and N, and the slowest jobs.  Run the
sweep on an otherwise idle machine: anything else running stretches the jobs'
wall times.  Snakemake's `cpu_time` column is not used: it is sampled every
30 s (snakemake.benchmark.BENCHMARK_INTERVAL), so it misses up to the last
30 s of each job.
"""

from __future__ import annotations

import argparse
import csv
import math
import re
from collections import defaultdict
from pathlib import Path


def _number(text: str | None) -> float:
    """A benchmark column as a float; NaN for 'NA' (job shorter than a sample)."""
    try:
        return float(text)
    except (TypeError, ValueError):
        return float("nan")


def read_jobs(root: Path) -> list[dict]:
    """One record per benchmark file: name, wall s, peak RSS MB, end time (file mtime)."""
    jobs = []
    for path in sorted(root.rglob("*.tsv")):
        with open(path, newline="") as fh:
            rows = list(csv.DictReader(fh, delimiter="\t"))
        if not rows:
            continue
        row = rows[-1]  # --benchmark-repeats would give several rows
        jobs.append({"name": str(path.relative_to(root).with_suffix("")),
                     "wall": float(row["s"]),
                     "rss_mb": _number(row.get("max_rss")),
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
    span = max(j["end"] for j in jobs) - min(j["end"] - j["wall"] for j in jobs)
    print(f"{len(jobs)} jobs; span {span:.0f} s ({span / 60:.1f} min); "
          f"summed job wall time {wall:.0f} s; peak RSS "
          f"{max((j['rss_mb'] for j in jobs if not math.isnan(j['rss_mb'])), default=math.nan):.0f} MB")
    groups: dict[str, list[float]] = defaultdict(lambda: [0, 0.0])
    for j in jobs:
        g = groups[group_of(j["name"])]
        g[0] += 1
        g[1] += j["wall"]
    print(f"\n{'group':<28} {'jobs':>5} {'wall s':>8} {'share %':>8}")
    for name, (count, w) in sorted(groups.items(), key=lambda kv: -kv[1][1]):
        print(f"{name:<28} {count:>5} {w:>8.0f} {100 * w / wall:>8.1f}")
    print(f"\n{'slowest jobs':<42} {'wall s':>8} {'RSS MB':>7}")
    for j in sorted(jobs, key=lambda j: -j["wall"])[: args.top]:
        print(f"{j['name']:<42} {j['wall']:>8.1f} {j['rss_mb']:>7.0f}")


if __name__ == "__main__":
    main()
