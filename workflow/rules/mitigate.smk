# Stage k >= 1 applies hypothesis k of the stack to stage k-1's survivors, the registered pair
# with the changes of stages 1..k-1, and writes what it changed: the rows it removed and the
# corrected coordinates of what it moved (changes.parquet), and its removed points as they were
# (removed.parquet). Never a copy of the survivors. Stage 0 applies no hypothesis: its points are
# the registered pair, and it has no mitigate job (nothing asks for its changes).
# Stage ids are content addresses, so an edited or appended hypothesis gets new folders and
# earlier stages are reused. A step that uses the study's grid (shadow without a grid of its
# own) carries it in its validated spec, so a grid edit changes that stage's id.


rule mitigate:
    input:
        registered=f"{RESULTS}/{{pair}}/registered.parquet",
        stage_changes=previous_stage_changes,
        plugin=plugin_source,
    output:
        changes=f"{RESULTS}/{{pair}}/stages/{{stage}}/changes.parquet",
        removed=f"{RESULTS}/{{pair}}/stages/{{stage}}/removed.parquet",
    log:
        f"{RESULTS}/logs/mitigate/{{pair}}/{{stage}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/mitigate/{{pair}}/{{stage}}.tsv"
    wildcard_constraints:
        stage=rf"(?!00-){STAGE_ID}",  # stage 0 changes nothing: no job
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=4000,
    params:
        step=stage_step,
        level=stage_level,
    shell:
        "lidarfield job mitigate --registered {input.registered:q} --stage-changes {input.stage_changes:q}"
        " --step {params.step:q} --stage {wildcards.stage} --level {params.level}"
        " --changes-out {output.changes:q} --removed-out {output.removed:q} > {log:q} 2>&1"
