# The pair explorer's data (lidarfield.report.explorer_data): the pair's sampled points (and the
# rest, loaded on the page's "show all") once, then one file per stage, so that appending a hypothesis writes only its stage's file. Written
# for the pairs whose page shows the figures (plots.pairs, or a stages.html asked for).


rule explorer_points:
    input:
        registered=f"{RESULTS}/{{pair}}/registered.parquet",
    output:
        points=f"{RESULTS}/{{pair}}/explorer/points.js",
        rest=f"{RESULTS}/{{pair}}/explorer/rest.js",
    log:
        f"{RESULTS}/logs/explorer_points/{{pair}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/explorer_points/{{pair}}.tsv"
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=2000,
    params:
        budget=EXPLORER_POINTS,
    shell:
        "lidarfield job explorer-points --registered {input.registered:q} --budget {params.budget}"
        " --out {output.points:q} --rest {output.rest:q} > {log:q} 2>&1"


rule explorer_stage:
    input:
        registered=f"{RESULTS}/{{pair}}/registered.parquet",
        field=f"{RESULTS}/{{pair}}/stages/{{stage}}/field.parquet",
        changes=stage_own_changes,
    output:
        f"{RESULTS}/{{pair}}/explorer/{{stage}}.js",
    log:
        f"{RESULTS}/logs/explorer_stage/{{pair}}/{{stage}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/explorer_stage/{{pair}}/{{stage}}.tsv"
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=2000,
    params:
        budget=EXPLORER_POINTS,
    shell:
        "lidarfield job explorer-stage --registered {input.registered:q} --field {input.field:q}"
        " --changes {input.changes:q} --budget {params.budget} --out {output:q} > {log:q} 2>&1"


# The report's own scripts, one copy for the study: the explorer's and
# the overview's, copied from the package.
rule report_js:
    output:
        explorer=f"{RESULTS}/assets/explorer.js",
        overview=f"{RESULTS}/assets/overview.js",
    log:
        f"{RESULTS}/logs/report_js.log",
    benchmark:
        f"{RESULTS}/benchmarks/report_js.tsv"
    localrule: True
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=500,
    shell:
        "lidarfield job report-js --out {output:q} > {log:q} 2>&1"
