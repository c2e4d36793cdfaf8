# The study-wide summary table, one page per pair, and the study overview (results/report.html).


rule summary:
    input:
        stats=all_stage_files("stats.json"),
        rematch=rematch_files,
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
        "lidarfield job summary --stats {input.stats:q} --rematch {input.rematch:q}"
        " --parquet {output.parquet:q}"
        " --csv {output.csv:q} > {log:q} 2>&1"


# A pair's page: report.html for every pair (with its pair and stage figures when plots.pairs
# selects it), stages.html on demand (always with them: asking for it draws them).
rule pair_report:
    input:
        stats=pair_stats,
        rematch=rematch_files,
        suggestions=pair_suggestions,
        pair_figures=pair_page_pair_figures,
        stage_figures=pair_page_stage_figures,
        explorer=pair_page_explorer,
    output:
        f"{RESULTS}/{{pair}}/{{page}}.html",
    log:
        f"{RESULTS}/logs/pair_report/{{pair}}/{{page}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/pair_report/{{pair}}/{{page}}.tsv"
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=1000,
    params:
        stage_dirs=pair_stage_dirs,
        plots=PLOTS,
        figures=figures_flag,
        on_demand=on_demand_page,
        max_mb=config["report"]["max_mb"],
    shell:
        "lidarfield job pair-report --pair {wildcards.pair} --stats {input.stats:q}"
        " --rematch {input.rematch:q} --suggestions {input.suggestions:q}"
        " --stage-dirs {params.stage_dirs:q} --plots {params.plots:q} {params.figures}"
        " --on-demand {params.on_demand:q} --max-mb {params.max_mb} --out {output:q} > {log:q} 2>&1"


rule report:
    input:
        summary=f"{RESULTS}/summary.parquet",
        voxels=f"{RESULTS}/study/voxels.parquet",
        hypotheses=f"{RESULTS}/study/hypotheses.parquet",
        pairs=f"{RESULTS}/study/pairs.parquet",
        figures=f"{RESULTS}/study/figures",
        suggestions=last_stage_suggestions,
        explain=explain_records,
        script=f"{RESULTS}/assets/overview.js",
    output:
        report(
            f"{RESULTS}/report.html",
            category="Study",
            labels={"report": "study overview"},
        ),
    log:
        f"{RESULTS}/logs/report.log",
    benchmark:
        f"{RESULTS}/benchmarks/report.tsv"
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=2000,
    params:
        config=canonical_json(config),
        plotted=canonical_json(PLOT_PAIRS),
        study_dir=study_dir,
    shell:
        # The config through stdin (printf is a shell builtin: no argument length limit).
        "printf '%s' {params.config:q} | lidarfield job report --config - --summary {input.summary:q}"
        " --study-dir {params.study_dir:q} --figures {input.figures:q}"
        " --plotted {params.plotted:q} --suggestions {input.suggestions:q}"
        " --explain {input.explain:q} --out {output:q} > {log:q} 2>&1"
