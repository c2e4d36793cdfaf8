# The study level, Parquet first: per stage level and voxel over the pairs (from the fields),
# per hypothesis and pair, the pairs ranked (from the summary); then the figures of them.


rule study_voxels:
    input:
        all_stage_files("field.parquet"),
    output:
        f"{RESULTS}/study/voxels.parquet",
    log:
        f"{RESULTS}/logs/study_voxels.log",
    benchmark:
        f"{RESULTS}/benchmarks/study_voxels.tsv"
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=4000,
    shell:
        "lidarfield job study-voxels --fields {input:q} --out {output:q} > {log:q} 2>&1"


rule study_tables:
    input:
        f"{RESULTS}/summary.parquet",
    output:
        hypotheses=f"{RESULTS}/study/hypotheses.parquet",
        pairs=f"{RESULTS}/study/pairs.parquet",
    log:
        f"{RESULTS}/logs/study_tables.log",
    benchmark:
        f"{RESULTS}/benchmarks/study_tables.tsv"
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=2000,
    shell:
        "lidarfield job study-tables --summary {input:q} --hypotheses-out {output.hypotheses:q}"
        " --pairs-out {output.pairs:q} > {log:q} 2>&1"


rule study_figures:
    input:
        summary=f"{RESULTS}/summary.parquet",
        voxels=f"{RESULTS}/study/voxels.parquet",
        hypotheses=f"{RESULTS}/study/hypotheses.parquet",
        pairs=f"{RESULTS}/study/pairs.parquet",
    output:
        report(
            directory(f"{RESULTS}/study/figures"),
            patterns=["{figure,[^/]+}.png"],  # not the page copies in page/
            category="Study",
            labels={"figure": "{figure}"},
        ),
    log:
        f"{RESULTS}/logs/study_figures.log",
    benchmark:
        f"{RESULTS}/benchmarks/study_figures.tsv"
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=2000,
    params:
        study_dir=study_dir,
    shell:
        "lidarfield job study-figures --summary {input.summary:q} --study-dir {params.study_dir:q}"
        " --out {output:q} > {log:q} 2>&1"
