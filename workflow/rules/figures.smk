rule fig5:
    """Fig. 5: F-d curves of the Fig. 5 brush with contact snapshots."""
    input:
        "results/sweep.nc",
    output:
        png=report(
            "results/figures/fig5.png",
            caption="../report/fig5.rst",
            category="Figures",
        ),
        pdf="results/figures/fig5.pdf",
    log:
        "logs/figures/fig5.log",
    benchmark:
        "results/benchmarks/figures/fig5.tsv"
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        figure="fig5",
        options=fig5_options(config),
        shape=fig5_shape(config),
    script:
        "../scripts/figure.py"


rule fig6:
    """Fig. 6: adhesive force against kbar with the rigid limit."""
    input:
        "results/sweep.nc",
    output:
        png=report(
            "results/figures/fig6.png",
            caption="../report/fig6.rst",
            category="Figures",
        ),
        pdf="results/figures/fig6.pdf",
    log:
        "logs/figures/fig6.log",
    benchmark:
        "results/benchmarks/figures/fig6.tsv"
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        figure="fig6",
        options={},
    script:
        "../scripts/figure.py"


rule fig7:
    """Fig. 7: soft-plateau adhesive force against N with N^(1/4)."""
    input:
        "results/sweep.nc",
    output:
        png=report(
            "results/figures/fig7.png",
            caption="../report/fig7.rst",
            category="Figures",
        ),
        pdf="results/figures/fig7.pdf",
    log:
        "logs/figures/fig7.log",
    benchmark:
        "results/benchmarks/figures/fig7.tsv"
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        figure="fig7",
        options={},
    script:
        "../scripts/figure.py"


rule fig8:
    """Fig. 8: work of separation against kbar with the soft limit."""
    input:
        "results/sweep.nc",
    output:
        png=report(
            "results/figures/fig8.png",
            caption="../report/fig8.rst",
            category="Figures",
        ),
        pdf="results/figures/fig8.pdf",
    log:
        "logs/figures/fig8.log",
    benchmark:
        "results/benchmarks/figures/fig8.tsv"
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        figure="fig8",
        options={},
    script:
        "../scripts/figure.py"


rule rough_figure:
    """Rough brushes: F_ad against roughness with the soft limit, against preload,
    and against the stiffness spread C."""
    input:
        "results/sweep.nc",
    output:
        png=report(
            "results/figures/{rough_figure}.png",
            caption="../report/rough.rst",
            category="Figures",
        ),
        pdf="results/figures/{rough_figure}.pdf",
    log:
        "logs/figures/{rough_figure}.log",
    benchmark:
        "results/benchmarks/figures/{rough_figure}.tsv"
    wildcard_constraints:
        rough_figure="rough_roughness|rough_preload|rough_spread",
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        figure=lambda wildcards: wildcards.rough_figure,
        options=lambda wildcards: dict(
            zip(("layout", "n_pillars"), rough_brush(config))
        ),
        flat=False,
    script:
        "../scripts/figure.py"


rule curve_figure:
    """Rough brushes: one approach-retract loop and its load sharing."""
    input:
        lambda wildcards: rough_example_curve(config),
    output:
        png=report(
            "results/figures/{curve_figure}.png",
            caption="../report/rough.rst",
            category="Figures",
        ),
        pdf="results/figures/{curve_figure}.pdf",
    log:
        "logs/figures/{curve_figure}.log",
    benchmark:
        "results/benchmarks/figures/{curve_figure}.tsv"
    wildcard_constraints:
        curve_figure="rough_loop|load_sharing",
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        figure=lambda wildcards: wildcards.curve_figure,
    script:
        "../scripts/curve_figure.py"


rule lattices:
    """F_ad against kbar for every layout and pillar shape of the same N."""
    input:
        "results/sweep.nc",
    output:
        png=report(
            "results/figures/lattices.png",
            caption="../report/lattices.rst",
            category="Figures",
        ),
        pdf="results/figures/lattices.pdf",
    log:
        "logs/figures/lattices.log",
    benchmark:
        "results/benchmarks/figures/lattices.tsv"
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        figure="lattices",
        options={},
        shape=None,
    script:
        "../scripts/figure.py"


rule rigid_phi:
    """The rigid limit F_ad (kbar = inf) against phi per N, with phi^(-1/4)."""
    input:
        "results/sweep.nc",
    output:
        png=report(
            "results/figures/rigid_phi.png",
            caption="../report/rigid_phi.rst",
            category="Figures",
        ),
        pdf="results/figures/rigid_phi.pdf",
    log:
        "logs/figures/rigid_phi.log",
    benchmark:
        "results/benchmarks/figures/rigid_phi.tsv"
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        figure="rigid_phi",
        options={},
    script:
        "../scripts/figure.py"
