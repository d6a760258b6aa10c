"""Time report of a finished sweep from Snakemake's benchmark files. Asserts nothing.

    python benchmarks/sweep_report.py                 # results/benchmarks of this checkout
    python benchmarks/sweep_report.py path/to/results/benchmarks --top 15
    python benchmarks/sweep_report.py --floor       # + the transforms' share
    python benchmarks/sweep_report.py new/results/benchmarks --against old/results/benchmarks

Prints the jobs' summed wall time, the span from the first job's start to
the last job's end (from file times: each benchmark file is written when its
job ends), the wall time per layout and N, and the slowest jobs.  With
``--floor`` it also reads the curve files beside the benchmark folder
(``results/curves``) and prints, per layout and N, what the curves'
operator applications would cost as bare transforms alone: each curve's
applications times one application's pruned transform pair, timed here on
one thread for the grid, mirror fold, precision and FFT library the curve
records.  That is the floor of today's algorithm (one residual per cascade
round, one per CG iteration); the rest of a curve's time is bookkeeping
and setup, and what a job takes beyond its curve's own wall time (the
process's start, imports, writing the file) is printed beside it.  Run the
sweep on an otherwise idle machine: anything else running stretches the jobs'
wall times.  With ``--against`` it sets another sweep's benchmark
folder beside this one (another version's, run side by side): job time per
layout, N and in all for the curves both ran, with the ratio, and from the
curve files beside the two folders how many F_ad and W agree within
``--within`` (default 2e-4, the project's rule for a change that is not
meant to change physics) and where they differ most.  Snakemake's `cpu_time` column is not used: it is sampled every
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


def pair_ms(grid: int, fold: int, single: bool, library: str, repeats: int = 30) -> float:
    """ms of one application's transform pair (whole grid or mirror
    quadrant), one thread, on this machine; the median of three timings."""
    from threadpoolctl import threadpool_limits

    from bench_speed import _ms
    from brushcore.numerics.halfspace.convolution import Convolver
    from brushcore.numerics.halfspace.mirror import MirrorConvolver
    with threadpool_limits(1):
        if fold == 4:
            conv, fill = MirrorConvolver(grid, single=single), grid // 2
        else:
            conv, fill = Convolver(grid, single=single, library=library), grid
        return sorted(_ms(conv, fill, repeats) for _ in range(3))[1]


def transform_floor(curves: Path, jobs: list[dict]) -> None:
    """Print, per layout and N, the curves' applications priced at
    `pair_ms` against their recorded wall time, and the jobs' time beyond
    it (``jobs`` from `read_jobs`, matched by the curve's path)."""
    import xarray as xr
    rows = []
    for path in sorted(curves.rglob("*.nc")):
        with xr.open_dataset(path) as ds:
            a = ds.attrs
            if "operator_applications" not in a or a.get("backend", "cpu") != "cpu":
                continue
            key = (int(a["grid"]), int(a.get("symmetry_fold", 1)),
                   a.get("fft_precision") == "single", str(a.get("fft_library_used", "fftw")))
            rows.append((f"{a['layout']}/N{int(a['n_pillars'])}", key,
                         int(a["operator_applications"]), float(a["wall_time_s"]),
                         str(Path("simulate") / path.relative_to(curves).with_suffix(""))))
    if not rows:
        raise SystemExit(f"no curve files under {curves}")
    prices = {key: pair_ms(*key) for key in sorted({r[1] for r in rows})}
    print("\none application's transform pair, one thread, here: " + "; ".join(
        f"{g}^2 {'quadrant' if f == 4 else 'whole grid'} {'float32' if s else 'float64'} "
        f"{lib} {ms:.2f} ms" for (g, f, s, lib), ms in prices.items()))
    job_wall = {j["name"]: j["wall"] for j in jobs}
    beyond = [job_wall[name] - wall for *_, wall, name in rows if name in job_wall]
    groups: dict[str, list[float]] = defaultdict(lambda: [0, 0, 0.0, 0.0])
    for group, key, apps, wall, _ in rows:
        g = groups[group]
        g[0] += 1
        g[1] += apps
        g[2] += wall
        g[3] += apps * prices[key] / 1e3
    print(f"{'layout/N':<16} {'curves':>6} {'apps':>8} {'curve s':>8} "
          f"{'transforms s':>12} {'share %':>8}")
    for name, (count, apps, wall, floor) in sorted(groups.items(), key=lambda kv: -kv[1][2]):
        print(f"{name:<16} {count:>6} {apps:>8} {wall:>8.0f} {floor:>12.0f} "
              f"{100 * floor / wall:>8.1f}")
    wall = sum(g[2] for g in groups.values())
    floor = sum(g[3] for g in groups.values())
    print(f"{'all':<16} {len(rows):>6} {sum(g[1] for g in groups.values()):>8} "
          f"{wall:>8.0f} {floor:>12.0f} {100 * floor / wall:>8.1f}")
    if beyond:
        print(f"the {len(beyond)} simulate jobs beyond their curves' wall time: "
              f"{sum(beyond):.0f} s in all, median {sorted(beyond)[len(beyond) // 2]:.2f} s a job")


def curve_key(name: str) -> tuple:
    """(group, kbar, seed, rest) of a simulate job's name, whatever the
    version's file naming: 'simulate/random/N1620_kbar1e-05_seed0' and
    'simulate/random/N1620_kbar1e-05_seed0_grid512_phi0.12' differ only in
    ``rest``, which `compare_times` drops where one sweep's names lack it."""
    match = re.match(r"(.*)_kbar([^_]+)_seed(\d+)(.*)$", name)
    if match is None:
        return (name, math.nan, -1, "")
    group, kbar, seed, rest = match.groups()
    return (group, float(kbar), int(seed), rest)


def compare_times(jobs: list[dict], other: list[dict]) -> dict[str, tuple[int, float, float]]:
    """Per simulate group and in all ('all'): (curves both sweeps ran, job
    wall time here [s], there [s]).  Curves are matched by layout, N, kbar
    and seed, and by grid and phi where both sweeps' names carry them."""
    def keyed(records: list[dict], plain: bool) -> dict[tuple, float]:
        out = {}
        for j in records:
            if not j["name"].startswith("simulate/"):
                continue
            key = curve_key(j["name"])
            out[key[:3] if plain else key] = j["wall"]
        return out
    plain = not all(curve_key(j["name"])[3] for j in jobs + other
                    if j["name"].startswith("simulate/"))
    here, there = keyed(jobs, plain), keyed(other, plain)
    table: dict[str, list] = defaultdict(lambda: [0, 0.0, 0.0])
    for key in set(here) & set(there):
        for group in (key[0], "all"):
            row = table[group]
            row[0] += 1
            row[1] += here[key]
            row[2] += there[key]
    return {group: tuple(row) for group, row in table.items()}


def compare_results(curves: Path, other: Path) -> list[tuple]:
    """(|dF_ad| / F_ad, |dW| / W, key) of every curve in both folders, by
    the curve files' whole case (`brushcore.data.aggregate.case_key`: layout,
    N, kbar, seed, grid, rough parameters, shape) and phi; largest |dW| first."""
    import xarray as xr

    from brushcore.data.aggregate import case_key

    def load(root: Path) -> dict[tuple, tuple[float, float]]:
        out = {}
        for path in sorted(root.rglob("*.nc")):
            with xr.open_dataset(path) as ds:
                if "adhesive_force_normalized" not in ds:
                    continue
                key = (case_key(ds), float(ds.attrs["phi"]))
                out[key] = (float(ds.adhesive_force_normalized),
                            float(ds.work_of_separation_normalized))
        return out
    here, there = load(curves), load(other)
    rows = [(abs(here[k][0] / there[k][0] - 1.0), abs(here[k][1] / there[k][1] - 1.0), k)
            for k in set(here) & set(there)]
    return sorted(rows, key=lambda row: -row[1])


def print_comparison(root: Path, other: Path, jobs: list[dict], within: float) -> None:
    """The ``--against`` report (see the module docstring)."""
    table = compare_times(jobs, read_jobs(other))
    if not table:
        raise SystemExit(f"no simulate job in both {root} and {other}")
    print(f"\nagainst {other}: job wall time of the curves both ran")
    print(f"{'group':<28} {'curves':>6} {'here s':>8} {'there s':>8} {'there/here':>10}")
    for name, (count, here, there) in sorted(table.items(), key=lambda kv: -kv[1][2]):
        print(f"{name:<28} {count:>6} {here:>8.0f} {there:>8.0f} {there / here:>10.2f}")
    rows = compare_results(root.parent / "curves", other.parent / "curves")
    if rows:
        print(f"F_ad within {within:g} on {sum(r[0] <= within for r in rows)} of {len(rows)} "
              f"curves, W on {sum(r[1] <= within for r in rows)}; largest differences:")
        for df, dw, key in rows[:5]:
            print(f"  W {dw:.2e}  F_ad {df:.2e}  {key}")


def group_of(name: str) -> str:
    """'simulate/random/N1620_kbar0.1_seed0' -> 'simulate/random/N1620'."""
    return re.sub(r"_kbar.*$", "", name)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("root", nargs="?", default="results/benchmarks", type=Path)
    parser.add_argument("--top", type=int, default=10, help="slowest jobs to list")
    parser.add_argument("--floor", action="store_true",
                        help="also price the curves' applications as bare transforms")
    parser.add_argument("--against", type=Path, metavar="OTHER",
                        help="another sweep's benchmark folder: time ratios and result agreement")
    parser.add_argument("--within", type=float, default=2e-4,
                        help="relative difference counted as agreement with --against")
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
    if args.floor:
        transform_floor(args.root.parent / "curves", jobs)
    if args.against is not None:
        print_comparison(args.root, args.against, jobs, args.within)


if __name__ == "__main__":
    main()
