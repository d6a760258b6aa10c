"""Helpers shared by the rules: the job list and resource estimates."""

import math


def check_regular_squares(config):
    """Stop before any job when a regular N is not a perfect square.

    JSON Schema cannot express "perfect square", so this completes the schema.
    """
    for key, values in (
        ("regular", config["regular"]),
        ("fig5.n_pillars", [config["fig5"]["n_pillars"]]),
    ):
        bad = [n for n in values if math.isqrt(n) ** 2 != n]
        if bad:
            raise ValueError(
                f"config key '{key}': N = {bad} not a perfect square; a regular "
                "layout needs sqrt(N) x sqrt(N) pillars (e.g. 64, 256, 576, 2304)"
            )


def kbar_tag(kbar):
    """File-name form of a stiffness: the shortest exact repr (1e-06, 0.455)."""
    return repr(float(kbar))


def sweep_cases(config):
    """Every (layout, n_pillars, kbar, seed) the config asks for, once.

    Regular layouts ignore the seed, so they run with seed 0 only; the Fig. 5
    brush adds its own kbar values to the regular sweep.
    """
    cases = set()
    for n in config["regular"]:
        for kbar in config["kbar"]:
            cases.add(("regular", n, kbar_tag(kbar), 0))
    fig5 = config["fig5"]
    for kbar in fig5["kbar"]:
        cases.add(("regular", fig5["n_pillars"], kbar_tag(kbar), 0))
    for n in config["random"]:
        for kbar in config["kbar"]:
            for seed in config["seeds"]:
                cases.add(("random", n, kbar_tag(kbar), seed))
    return sorted(cases, key=lambda c: (c[0], c[1], float(c[2]), c[3]))


def curve_files(config):
    """The curve file of every case of the sweep."""
    return [
        f"results/curves/{layout}/N{n}_kbar{kbar}_seed{seed}.nc"
        for layout, n, kbar, seed in sweep_cases(config)
    ]


def simulate_mem_mb(wildcards, attempt):
    """Memory of one simulation [MB], doubled on a retry.

    Measured peak RSS at grid 512: 0.18-0.31 GB, 0.56 GB for 48 x 48 pillars
    (pillar-interaction matrices); FFT buffers and blocks scale with n^2.
    """
    grid = config["grid"]
    return int(400 + 800 * (grid / 512) ** 2) * attempt


def simulate_runtime(wildcards, attempt):
    """Wall-time limit of one simulation [min], doubled on a retry.

    Measured at grid 512 on one core: 2-150 s per curve; the cost grows
    about as n^3 (solves ~ n, each ~ n^2 log n).
    """
    grid = config["grid"]
    return int(5 + 15 * (grid / 512) ** 3) * attempt
