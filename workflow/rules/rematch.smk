# Does a stage's mitigation help scan matching? Register its survivors again with each method of
# the config's rematch section, from the reference pose moved by seeded offsets, and measure the
# pose error. Requested only when the config has `rematch:`; its params are the rematch settings,
# so it reruns when they or its stage change, and never because of the grid or the plots.


rule rematch:
    input:
        registered=f"{RESULTS}/{{pair}}/registered.parquet",
        stage_changes=stage_changes,
    output:
        f"{RESULTS}/{{pair}}/stages/{{stage}}/rematch.parquet",
    log:
        f"{RESULTS}/logs/rematch/{{pair}}/{{stage}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/rematch/{{pair}}/{{stage}}.tsv"
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=4000,
    params:
        settings=REMATCH,
    shell:
        "lidarfield job rematch --registered {input.registered:q} --stage-changes {input.stage_changes:q} --stage {wildcards.stage} --settings {params.settings:q}"
        " --out {output:q} > {log:q} 2>&1"
