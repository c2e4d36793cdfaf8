# lidarfield explain for the pairs of the study, on demand: `snakemake explain` (every pair) or
# `snakemake results/{pair}/explain/explain.html` (one). From the pair's registered points, the
# loop applies the best suggestion worth it until the field is random or nothing helps (the
# config's explain settings). Once built, the study report shows what it found.

# The config's suggest list (null: the default candidates) and explain settings.
SUGGEST = canonical_json(STUDY.suggest)
EXPLAIN = canonical_json(STUDY.config["explain"])


def explain_dir(pair):
    return f"{RESULTS}/{pair}/explain"


@planned
def this_explain_dir(wildcards):
    return explain_dir(wildcards.pair)


@planned
def explain_plugin_sources(wildcards):
    """A plugin candidate's file is an input of explain: editing it explains again."""
    return [step["plugin"]["file"] for step in STUDY.suggest or [] if "plugin" in step]


@planned
def explain_records(wildcards):
    """The pairs' explain.json that exist: the study report shows them, and is kept up to date
    with them, once `snakemake explain` (or one pair's target) has built them."""
    records = [f"{explain_dir(pair)}/explain.json" for pair in PAIRS]
    return [record for record in records if Path(record).is_file()]


rule explain_pair:
    input:
        points=f"{RESULTS}/{{pair}}/registered.parquet",
        plugins=explain_plugin_sources,
    output:
        stack=f"{RESULTS}/{{pair}}/explain/stack.yaml",
        steps=f"{RESULTS}/{{pair}}/explain/steps.csv",
        record=f"{RESULTS}/{{pair}}/explain/explain.json",
        page=f"{RESULTS}/{{pair}}/explain/explain.html",
        figures=directory(f"{RESULTS}/{{pair}}/explain/figures"),
    log:
        f"{RESULTS}/logs/explain/{{pair}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/explain/{{pair}}.tsv"
    conda:
        "../envs/lidarfield.yaml"
    threads: 1
    resources:
        mem_mb=4000,
    params:
        out_dir=this_explain_dir,
        grid=GRID,
        suggest=SUGGEST,
        settings=EXPLAIN,
        plots=PLOTS,
    shell:
        "lidarfield job explain --points {input.points:q} --pair {wildcards.pair} --grid {params.grid:q}"
        " --suggest {params.suggest:q} --settings {params.settings:q} --plots {params.plots:q}"
        " --out-dir {params.out_dir:q} > {log:q} 2>&1"


rule explain:
    input:
        expand(f"{RESULTS}/{{pair}}/explain/explain.html", pair=PAIRS),
