# What to try next: every candidate hypothesis applied on its own to a stage's survivors, and
# the field it would leave. A rule of its own so that it never delays the stages: the next
# stage's mitigate job does not wait for it. The pairs that suggest_pairs selects get their last
# stage's suggestions (the study's next steps); those that plots.pairs selects get every stage's,
# as any pair's stages.html does when it is asked for (pair_suggestions in common.smk), stage by
# stage (suggest_priority), so that a stage with the points of the one before reuses its rows.


rule suggest:
    input:
        registered=f"{RESULTS}/{{pair}}/registered.parquet",
        stage_changes=stage_changes,
        plugins=candidate_plugin_sources,
    output:
        f"{RESULTS}/{{pair}}/stages/{{stage}}/suggestions.parquet",
    log:
        f"{RESULTS}/logs/suggest/{{pair}}/{{stage}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/suggest/{{pair}}/{{stage}}.tsv"
    priority: suggest_priority
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
        " --stage {wildcards.stage}"
        " --candidates {params.candidates:q} {params.defaults}"
        " --grid {params.grid:q} --out {output:q} > {log:q} 2>&1"
