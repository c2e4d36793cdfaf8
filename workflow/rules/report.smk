# The study-wide summary table and the self-contained HTML report.


rule summary:
    input:
        all_stage_files("stats.json"),
    output:
        parquet=f"{RESULTS}/summary.parquet",
        csv=report(
            f"{RESULTS}/summary.csv", category="Study", labels={"table": "summary"}
        ),
    log:
        f"{RESULTS}/logs/summary.log",
    benchmark:
        f"{RESULTS}/benchmarks/summary.tsv"
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=2000,
    shell:
        "lidarfield job summary --stats {input:q} --parquet {output.parquet:q}"
        " --csv {output.csv:q} > {log:q} 2>&1"


rule report:
    input:
        summary=f"{RESULTS}/summary.parquet",
        stage_figures=all_stage_files("figures"),
        suggestions=all_stage_files("suggestions.parquet"),
        pair_figures=expand(f"{RESULTS}/{{pair}}/figures", pair=PAIRS),
    output:
        report(
            f"{RESULTS}/report.html",
            category="Study",
            labels={"report": "study report"},
        ),
    log:
        f"{RESULTS}/logs/report.log",
    benchmark:
        f"{RESULTS}/benchmarks/report.tsv"
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=4000,
    params:
        study=canonical_json({"config": config, "stages": STAGES}),
        results=results_dir,
    shell:
        "lidarfield job report --study {params.study:q} --results {params.results:q} --out {output:q} > {log:q} 2>&1"
