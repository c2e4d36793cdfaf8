# Voxelize both clouds of a stage on the study's grid and diff them: the discrepancy field and
# its summary row. Only the grid settings are params, so a grid edit reruns only this and after.
# The stage before's field is an input: a stage whose hypothesis removed and moved nothing (the
# same points digest) takes its columns instead of computing them again.


rule field:
    input:
        registered=f"{RESULTS}/{{pair}}/registered.parquet",
        stage_changes=stage_changes,
        removed=stage_removed,
        previous=previous_stage_file("field.parquet"),
    output:
        field=f"{RESULTS}/{{pair}}/stages/{{stage}}/field.parquet",
        stats=f"{RESULTS}/{{pair}}/stages/{{stage}}/stats.json",
    log:
        f"{RESULTS}/logs/field/{{pair}}/{{stage}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/field/{{pair}}/{{stage}}.tsv"
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=4000,
    params:
        grid=GRID,
    shell:
        "lidarfield job field --registered {input.registered:q} --stage-changes {input.stage_changes:q}"
        " --stage {wildcards.stage} --removed {input.removed:q} --previous {input.previous:q}"
        " --grid {params.grid:q} --pair {wildcards.pair} --field-out {output.field:q}"
        " --stats-out {output.stats:q} > {log:q} 2>&1"
