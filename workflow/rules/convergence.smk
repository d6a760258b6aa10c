rule convergence:
    """Mesh-refinement study: F_ad and W per case extrapolated to h -> 0."""
    input:
        "results/sweep.nc",
    output:
        nc="results/convergence.nc",
        csv=report(
            "results/convergence.csv",
            caption="../report/convergence.rst",
            category="Convergence",
        ),
        md="results/convergence.md",
        png=report(
            "results/figures/convergence.png",
            caption="../report/convergence.rst",
            category="Convergence",
        ),
        pdf="results/figures/convergence.pdf",
    log:
        "logs/convergence.log",
    benchmark:
        "results/benchmarks/convergence.tsv"
    resources:
        mem_mb=2000,
        runtime=10,
    script:
        "../scripts/convergence.py"
