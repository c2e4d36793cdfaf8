# What to try next, per stage: every candidate hypothesis applied on its own to the stage's
# survivors, and the field it would leave. A rule of its own so that it never delays the
# stages: the next stage's mitigate job does not wait for it. It also writes what its stage
# changed in the carried neighbour distances (empty without an outliers candidate), which
# the next stage's suggest job starts from.


# The outliers candidate's nearest-neighbour search, once per pair on the registered points:
# each stage's suggest job carries the distances past what its own stage removed (exact),
# from the changes the stages before it recorded, instead of searching again.
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
        registered=f"{RESULTS}/{{pair}}/registered.parquet",
        stage_changes=stage_changes,
        neighbours=pair_neighbours,
        removed=removed_up_to_stage,
        changes=changes_before_stage,
        plugins=candidate_plugin_sources,
    output:
        suggestions=f"{RESULTS}/{{pair}}/stages/{{stage}}/suggestions.parquet",
        changes=f"{RESULTS}/{{pair}}/stages/{{stage}}/neighbour_changes.parquet",
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
        "lidarfield job suggest --registered {input.registered:q} --stage-changes {input.stage_changes:q}"
        " --candidates {params.candidates:q} {params.defaults}"
        " --grid {params.grid:q} --neighbours={input.neighbours:q} --removed {input.removed:q}"
        " --changes {input.changes:q} --out {output.suggestions:q} --changes-out {output.changes:q} > {log:q} 2>&1"
