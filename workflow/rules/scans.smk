# Stage 1 of the pipeline: every scan of the study as a scan Parquet (points in its sensor frame).


rule simulate:
    output:
        f"{RESULTS}/scans/simulated/{{scan}}.parquet",
    log:
        f"{RESULTS}/logs/simulate/{{scan}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/simulate/{{scan}}.tsv"
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=2000,
    params:
        spec=scan_spec,
    shell:
        "lidarfield job simulate --spec {params.spec:q} --out {output:q} > {log:q} 2>&1"


rule ingest:
    output:
        f"{RESULTS}/scans/recorded/{{scan}}.parquet",
    log:
        f"{RESULTS}/logs/ingest/{{scan}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/ingest/{{scan}}.tsv"
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=2000,
    params:
        spec=scan_spec,
    shell:
        "lidarfield job ingest --spec {params.spec:q} --out {output:q} > {log:q} 2>&1"
