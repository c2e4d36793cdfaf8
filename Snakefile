# lidarfield: discrepancy-vector fields of registered lidar scan pairs, stage by stage through
# a stack of hypotheses. `snakemake --cores 2` runs the default study (config/config.yaml);
# `snakemake --cores 2 --configfile config/expd.yaml` runs another one instead.


include: "workflow/rules/common.smk"
include: "workflow/rules/worker.smk"
include: "workflow/rules/scans.smk"
include: "workflow/rules/register.smk"
include: "workflow/rules/mitigate.smk"
include: "workflow/rules/field.smk"
include: "workflow/rules/suggest.smk"
include: "workflow/rules/rematch.smk"
include: "workflow/rules/plot.smk"
include: "workflow/rules/study.smk"
include: "workflow/rules/explain.smk"
include: "workflow/rules/explorer.smk"
include: "workflow/rules/report.smk"


rule all:
    default_target: True
    input:
        f"{RESULTS}/report.html",
        expand(f"{RESULTS}/{{pair}}/report.html", pair=PAIRS),
