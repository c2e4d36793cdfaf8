# lidarfield explain for the pairs of the study, on demand: `snakemake explain` (every pair) or
# `snakemake results/{pair}/explain/explain.html` (one). From the pair's registered points, the
# loop applies the best suggestion worth it until the field is random or nothing helps (the
# config's explain settings). Once built, the study report shows what it found.


rule explain_pair:
    input:
        points=f"{RESULTS}/{{pair}}/registered.parquet",
        plugins=explain_plugin_sources,
    output:
        stack=f"{RESULTS}/{{pair}}/explain/stack.yaml",
        steps=f"{RESULTS}/{{pair}}/explain/steps.csv",
        record=f"{RESULTS}/{{pair}}/explain/explain.json",
        page=f"{RESULTS}/{{pair}}/explain/explain.html",
        figures=directory(f"{RESULTS}/{{pair}}/explain/figures"),
    log:
        f"{RESULTS}/logs/explain/{{pair}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/explain/{{pair}}.tsv"
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=4000,
    params:
        out_dir=this_explain_dir,
        grid=GRID,
        suggest=SUGGEST,
        settings=EXPLAIN,
        plots=PLOTS,
    shell:
        "lidarfield job explain --points {input.points:q} --pair {wildcards.pair} --grid {params.grid:q}"
        " --suggest {params.suggest:q} --settings {params.settings:q} --plots {params.plots:q}"
        " --out-dir {params.out_dir:q} > {log:q} 2>&1"


rule explain:
    input:
        expand(f"{RESULTS}/{{pair}}/explain/explain.html", pair=PAIRS),
