rule simulate:
    """One pull-off simulation: one (layout, N, kbar, seed) -> one curve file."""
    output:
        "results/curves/{layout}/N{n_pillars}_kbar{kbar}_seed{seed}.nc",
    log:
        "logs/simulate/{layout}/N{n_pillars}_kbar{kbar}_seed{seed}.log",
    benchmark:
        "results/benchmarks/simulate/{layout}/N{n_pillars}_kbar{kbar}_seed{seed}.tsv"
    wildcard_constraints:
        layout="regular|random",
        n_pillars=r"[0-9]+",
        kbar=r"[0-9][0-9.e+-]*",
        seed=r"[0-9]+",
    threads: config["threads"]
    resources:
        mem_mb=simulate_mem_mb,
        runtime=simulate_runtime,
    params:
        grid=config["grid"],
        phi=config["phi"],
        solver=config["solver"],
    script:
        "../scripts/simulate.py"
