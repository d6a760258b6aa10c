rule simulate:
    """One pull-off simulation: one (layout, N, kbar, seed, grid, phi, shape, rough) -> one curve file."""
    input:
        simulate_inputs(config),
    output:
        f"results/curves/{CURVE_NAME}.nc",
    log:
        f"logs/simulate/{CURVE_NAME}.log",
    benchmark:
        f"results/benchmarks/simulate/{CURVE_NAME}.tsv"
    wildcard_constraints:
        layout=r"regular|hexagonal|random|file_[A-Za-z0-9._-]+",
        n_pillars=r"[0-9]+",
        kbar=r"[0-9][0-9.e+-]*|inf",
        seed=r"[0-9]+",
        grid=r"[0-9]+",
        phi=r"[0-9][0-9.e+-]*",
        shape=r"(_square(_-?[0-9][0-9.e+-]*)?|_ellipse[0-9][0-9.e+-]*_-?[0-9][0-9.e+-]*)?",
        rough=r"(_S[0-9][0-9.e+-]*_P[0-9][0-9.e+-]*_C[0-9][0-9.e+-]*(_Q[0-9a-f]{8})?)?",
    threads: config["threads"]
    resources:
        mem_mb=simulate_mem_mb(config),
        runtime=simulate_runtime(config),
        gpu=simulate_gpus(config),
        gres=simulate_gres(config),
    params:
        solver=config["solver"],
        rough=lambda wildcards: parse_rough_tag(wildcards.rough),
        shape=lambda wildcards: parse_shape_tag(wildcards.shape),
        layout_file=lambda wildcards: brush_files(config, wildcards.layout),
    # allow_coarse and backend are read from the config by the script, not
    # passed as params: they change no curve (a coarse case runs the same
    # once allowed; a GPU curve is a CPU one within CG's tolerance), so a
    # change must not rerun the finished ones.
    script:
        "../scripts/simulate.py"
