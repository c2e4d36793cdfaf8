# Stage k applies hypothesis k of the stack to stage k-1's survivors (stage 0: no mitigation).
# Stage ids are content addresses, so an edited or appended hypothesis gets new folders and
# earlier stages are reused. A step that uses the study's grid (shadow without a grid of its
# own) carries it in its validated spec, so a grid edit changes that stage's id.


rule mitigate:
    input:
        points=previous_stage_points,
        plugin=plugin_source,
    output:
        points=f"{RESULTS}/{{pair}}/stages/{{stage}}/points.parquet",
        removed=f"{RESULTS}/{{pair}}/stages/{{stage}}/removed.parquet",
    log:
        f"{RESULTS}/logs/mitigate/{{pair}}/{{stage}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/mitigate/{{pair}}/{{stage}}.tsv"
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=4000,
    params:
        step=stage_step,
        level=stage_level,
    shell:
        "lidarfield job mitigate --points-in {input.points:q} --step {params.step:q}"
        " --stage {wildcards.stage} --level {params.level}"
        " --points-out {output.points:q} --removed-out {output.removed:q} > {log:q} 2>&1"
