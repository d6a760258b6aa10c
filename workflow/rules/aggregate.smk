rule aggregate:
    """Collect every curve file into results/sweep.nc."""
    input:
        curve_files(config),
    output:
        "results/sweep.nc",
    log:
        "logs/aggregate.log",
    benchmark:
        "results/benchmarks/aggregate.tsv"
    resources:
        mem_mb=4000,
        runtime=30,
    params:
        keep_snapshots=snapshot_brushes(config),
        cases=[named_case(case) for case in sweep_cases(config)],  # as curve_files lists them
    script:
        "../scripts/aggregate.py"


rule summary:
    """Headline numbers beside the paper's."""
    input:
        "results/sweep.nc",
    output:
        csv=report(
            "results/summary.csv",
            caption="../report/summary.rst",
            category="Summary",
        ),
        md="results/summary.md",
    log:
        "logs/summary.log",
    benchmark:
        "results/benchmarks/summary.tsv"
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        fig5=fig5_options(config),  # its shape as a label, as the Fig. 5 figure takes it
    script:
        "../scripts/summary.py"
