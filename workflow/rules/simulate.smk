rule simulate:
    """One pull-off simulation: one (layout, N, kbar, seed, grid, phi) -> one curve file."""
    output:
        f"results/curves/{CURVE_NAME}.nc",
    log:
        f"logs/simulate/{CURVE_NAME}.log",
    benchmark:
        f"results/benchmarks/simulate/{CURVE_NAME}.tsv"
    wildcard_constraints:
        layout="regular|random",
        n_pillars=r"[0-9]+",
        kbar=r"[0-9][0-9.e+-]*|inf",
        seed=r"[0-9]+",
        grid=r"[0-9]+",
        phi=r"[0-9][0-9.e+-]*",
    threads: config["threads"]
    resources:
        mem_mb=simulate_mem_mb,
        runtime=simulate_runtime,
    params:
        solver=config["solver"],
        allow_coarse=config["allow_coarse"],
    script:
        "../scripts/simulate.py"
