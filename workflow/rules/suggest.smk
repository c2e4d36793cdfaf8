# What to try next, per stage: every candidate hypothesis applied on its own to the stage's
# survivors, and the field it would leave. A rule of its own so that it never delays the
# stages: the next stage's mitigate job does not wait for it.


rule suggest:
    input:
        points=f"{RESULTS}/{{pair}}/stages/{{stage}}/points.parquet",
        plugins=candidate_plugin_sources,
    output:
        f"{RESULTS}/{{pair}}/stages/{{stage}}/suggestions.parquet",
    log:
        f"{RESULTS}/logs/suggest/{{pair}}/{{stage}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/suggest/{{pair}}/{{stage}}.tsv"
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=4000,
    params:
        candidates=stage_candidates,
        defaults=CANDIDATES_FLAG,
        grid=GRID,
    shell:
        "lidarfield job suggest --points {input.points:q} --candidates {params.candidates:q} {params.defaults}"
        " --grid {params.grid:q} --out {output:q} > {log:q} 2>&1"
