# What to try next, per stage: every candidate hypothesis applied on its own to the stage's
# survivors, and the field it would leave. A rule of its own so that it never delays the
# stages: the next stage's mitigate job does not wait for it.


# The outliers candidate's nearest-neighbour search, once per pair on the registered points:
# each stage's suggest job carries the distances past what its stages removed (exact) instead
# of searching again.
rule neighbours:
    input:
        f"{RESULTS}/{{pair}}/registered.parquet",
    output:
        f"{RESULTS}/{{pair}}/neighbours.parquet",
    log:
        f"{RESULTS}/logs/neighbours/{{pair}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/neighbours/{{pair}}.tsv"
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=2000,
    params:
        k=NEIGHBOUR_COUNTS,
    shell:
        "lidarfield job neighbours --points {input:q} --k {params.k} --out {output:q} > {log:q} 2>&1"


rule suggest:
    input:
        points=f"{RESULTS}/{{pair}}/stages/{{stage}}/points.parquet",
        neighbours=pair_neighbours,
        removed=removed_up_to_stage,
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
        " --grid {params.grid:q} --neighbours={input.neighbours:q} --removed {input.removed:q}"
        " --out {output:q} > {log:q} 2>&1"
