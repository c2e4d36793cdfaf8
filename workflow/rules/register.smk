# Scan 2 expressed in scan 1's frame, keeping the pose of sensor 2 (mitigations need both origins).


rule register:
    input:
        unpack(pair_scans),
    output:
        f"{RESULTS}/{{pair}}/registered.parquet",
    log:
        f"{RESULTS}/logs/register/{{pair}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/register/{{pair}}.tsv"
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=4000,
    params:
        settings=registration,
    shell:
        "lidarfield job register --scan1 {input.scan1:q} --scan2 {input.scan2:q}"
        " --settings {params.settings:q} --out {output:q} > {log:q} 2>&1"
