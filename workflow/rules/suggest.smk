# What to try next, per stage: every candidate hypothesis applied on its own to the stage's
# survivors, and the field it would leave. A rule of its own so that it never delays the
# stages: the next stage's mitigate job does not wait for it. Each stage's suggestions pass
# their outlier candidate's neighbour distances to the next stage's (neighbours.parquet),
# which carries them past the points its hypothesis removed instead of searching again.


rule suggest:
    input:
        points=f"{RESULTS}/{{pair}}/stages/{{stage}}/points.parquet",
        removed=f"{RESULTS}/{{pair}}/stages/{{stage}}/removed.parquet",
        previous_neighbours=previous_stage_file("neighbours.parquet"),
        plugins=candidate_plugin_sources,
    output:
        suggestions=f"{RESULTS}/{{pair}}/stages/{{stage}}/suggestions.parquet",
        neighbours=f"{RESULTS}/{{pair}}/stages/{{stage}}/neighbours.parquet",
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
        " --grid {params.grid:q} --out {output.suggestions:q} --neighbours-out {output.neighbours:q}"
        " --previous-neighbours={input.previous_neighbours:q} --removed {input.removed:q} > {log:q} 2>&1"
