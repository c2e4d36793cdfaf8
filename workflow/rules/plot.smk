# The figures of each stage (field, removed points, largest voxels, before/after, 3-D view)
# and the stage-by-stage figures of each pair.


rule plot_stage:
    input:
        field=f"{RESULTS}/{{pair}}/stages/{{stage}}/field.parquet",
        registered=f"{RESULTS}/{{pair}}/registered.parquet",
        stage_changes=stage_changes,
        removed=stage_removed,
        previous=previous_stage_file("field.parquet"),
        plotly=f"{RESULTS}/assets/plotly.min.js",
    output:
        report(
            directory(f"{RESULTS}/{{pair}}/stages/{{stage}}/figures"),
            patterns=["{figure,[^/]+}.png"],  # not the page copies in page/
            category="Stage figures",
            subcategory="{pair}",
            labels={"pair": "{pair}", "stage": "{stage}", "figure": "{figure}"},
        ),
    log:
        f"{RESULTS}/logs/plot_stage/{{pair}}/{{stage}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/plot_stage/{{pair}}/{{stage}}.tsv"
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=3000,
    params:
        stage=this_stage_dir,
        previous=previous_stage_dir,
        plots=PLOTS,
    shell:
        "lidarfield job plot-stage --registered {input.registered:q} --stage-changes {input.stage_changes:q}"
        " --stage-dir {params.stage:q}"
        " --previous={params.previous:q} --plots {params.plots:q} --plotly-js {input.plotly:q}"
        " --out {output:q} > {log:q} 2>&1"


# One plotly.js for the study's 3-D views, which load it by relative path. A copy of a file from
# the plotly package: on a cluster it runs where Snakemake runs, and so keeps the pairs' job
# groups (profiles/slurm) from waiting for a submission of its own.
rule plotly_js:
    output:
        f"{RESULTS}/assets/plotly.min.js",
    log:
        f"{RESULTS}/logs/plotly_js.log",
    benchmark:
        f"{RESULTS}/benchmarks/plotly_js.tsv"
    localrule: True
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=500,
    shell:
        "lidarfield job plotly-js --out {output:q} > {log:q} 2>&1"


rule plot_pair:
    input:
        stats=pair_stats,
        rematch=rematch_files,
    output:
        report(
            directory(f"{RESULTS}/{{pair}}/figures"),
            patterns=["{figure,[^/]+}.png"],  # not the page copies in page/
            category="Pairs",
            labels={"pair": "{pair}", "figure": "{figure}"},
        ),
    log:
        f"{RESULTS}/logs/plot_pair/{{pair}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/plot_pair/{{pair}}.tsv"
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=2000,
    shell:
        "lidarfield job plot-pair --stats {input.stats:q} --rematch {input.rematch:q}"
        " --out {output:q} > {log:q} 2>&1"
