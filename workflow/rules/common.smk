# Config validation and the input/params functions of every rule.
import gc
import inspect
import sys
from pathlib import Path

import yaml
from snakemake.common import overwrite_function_params
from snakemake.utils import min_version, update_config

import lidarfield.study.config
from lidarfield.storage.stage_ids import canonical_json
from lidarfield.storage.layout import RESULTS_FOLDERS
from lidarfield.plots.settings import figure_settings

min_version("9.0")

# Planning makes millions of objects that live for the whole run, and Python's cyclic garbage
# collector would walk them again and again: 30% of the CPU of planning a 1,000-pair drive
# (bench/RESULTS.md). Off while Snakemake plans; the run's start (onstart, worker.smk) freezes
# what planning made and turns it back on.
gc.disable()


# The default study, with the keys of --config on top (Snakemake's convention: `--config
# results=DIR`, or a nested key such as `grid="{azimuth_bins: 18}"`, changes only that key). A
# study named with --configfile replaces it: the directive would merge the default's pairs
# into theirs.
if not workflow.overwrite_configfiles:

    configfile: "config/config.yaml"


def nested_config_overrides(config_args):
    """The nested values of --config's key=value pairs, read as YAML: Snakemake reads them with
    YAML's base loader, which leaves every number in `grid={azimuth_bins: 18}` a string.
    """
    overrides = {}
    for arg in config_args or ():
        key, _, value = arg.partition("=")
        try:
            parsed = yaml.safe_load(value)
        except yaml.YAMLError:
            continue  # Snakemake's reading (a string) stands
        if isinstance(parsed, (dict, list)):
            overrides[key] = parsed
    return overrides


update_config(config, nested_config_overrides(workflow.config_settings.config_args))


# Validated once against workflow/schemas/config.schema.yaml, with defaults filled in: the
# same function validates the config of `lidarfield run`. Relative paths are relative to the
# working directory. An invalid config is one line and exit status 2, as in the CLI (raised,
# Snakemake would add the stack frames of this file and of the package).
try:
    STUDY = lidarfield.study.config.validate_config(
        config,
        base_dir=Path.cwd(),
        source=", ".join(map(str, workflow.configfiles)) or "config",
    )
except lidarfield.errors.LidarfieldError as error:
    print(f"lidarfield: error: {error}", file=sys.stderr)
    sys.exit(2)
RESULTS = config["results"]
PAIRS = sorted(STUDY.pairs)
STAGES = {pair: STUDY.stage_ids(pair) for pair in PAIRS}
# Each stage level's suggestion candidates, validated once here rather than in every job's
# params (that was 8% of planning a 300-pair study).
CANDIDATES = [STUDY.candidates(level) for level in range(len(STUDY.hypotheses) + 1)]
# Default candidates (no suggest: section) that cannot apply to a pair are skipped, not errors.
CANDIDATES_FLAG = "--default-candidates" if STUDY.suggest is None else ""
# The pairs whose stage figures and every stage's suggestions the study makes (plots.pairs), and
# those with their last stage's (suggest_pairs and the plotted ones); any other pair's are made
# on demand, by asking for its page with them: results/{pair}/stages.html.
PLOT_PAIRS = STUDY.plot_pairs
SUGGEST_PAIRS = set(STUDY.suggest_pairs)


# A stage's id: {k:02d}-{hypothesis}-{hash8} (lidarfield.storage.stage_ids).
STAGE_ID = r"\d\d-[A-Za-z0-9_]+-[0-9a-f]{8}"


# A pair is any folder of the results but the study's own. Not the list of the pairs: Snakemake
# writes a constraint into every path pattern, and matching a list of 1,000 names made
# planning a 1,000-pair study take minutes.
wildcard_constraints:
    pair=rf"(?!(?:{'|'.join(RESULTS_FOLDERS)})/)[A-Za-z0-9][A-Za-z0-9_.-]*",
    stage=STAGE_ID,
    scan=r"[A-Za-z0-9][A-Za-z0-9_.-]*",
    page="report|stages",


def planned(function):
    """An input or params function, with its signature given to Snakemake once: Snakemake
    inspects it at every job it plans otherwise (8% of planning a 300-pair study)."""
    overwrite_function_params(function, inspect.signature(function).parameters)
    return function


def scan_path(scan):
    return f"{RESULTS}/scans/{scan.kind}/{scan.id}.parquet"


@planned
def scan_spec(wildcards):
    return canonical_json(STUDY.scans[wildcards.scan].spec)


@planned
def pair_scans(wildcards):
    pair = STUDY.pairs[wildcards.pair]
    return {"scan1": scan_path(pair.scan1), "scan2": scan_path(pair.scan2)}


@planned
def registration(wildcards):
    return canonical_json(STUDY.pairs[wildcards.pair].register)


@planned
def stage_level(wildcards):
    return STAGES[wildcards.pair].index(wildcards.stage)


def stage_dir(pair, stage):
    return f"{RESULTS}/{pair}/stages/{stage}"


@planned
def this_stage_dir(wildcards):
    return stage_dir(wildcards.pair, wildcards.stage)


@planned
def stage_changes(wildcards):
    """Stage k's points are the registered pair with the changes of stages 1..k (stage 0
    changes nothing: it has no mitigate job and no changes file)."""
    stages = STAGES[wildcards.pair][1 : stage_level(wildcards) + 1]
    return [f"{stage_dir(wildcards.pair, stage)}/changes.parquet" for stage in stages]


@planned
def previous_stage_changes(wildcards):
    """What stage k >= 1 starts from: the registered pair with the changes of stages 1..k-1."""
    return stage_changes(wildcards)[:-1]


@planned
def stage_removed(wildcards):
    """The points stage k removed: none for stage 0."""
    if stage_level(wildcards) == 0:
        return []
    return f"{this_stage_dir(wildcards)}/removed.parquet"


# Each stage level's step as its job's params (canonical JSON), made once here rather than at
# every mitigate job planned (1.5% of planning a 1,000-pair drive).
STEPS = [canonical_json(step) for step in (None, *STUDY.hypotheses)]


@planned
def stage_step(wildcards):
    return STEPS[stage_level(wildcards)]


@planned
def plugin_source(wildcards):
    """A plugin hypothesis's file is an input of its stage: editing it reruns the stage."""
    level = stage_level(wildcards)
    step = STUDY.hypotheses[level - 1] if level else {}
    return [step["plugin"]["file"]] if "plugin" in step else []


@planned
def stage_candidates(wildcards):
    """The candidate hypotheses of a stage's suggestions (canonical JSON)."""
    return canonical_json(CANDIDATES[stage_level(wildcards)])


@planned
def candidate_plugin_sources(wildcards):
    """A plugin candidate's file is an input of the suggestions: editing it reruns them."""
    return [
        step["plugin"]["file"]
        for step in CANDIDATES[stage_level(wildcards)]
        if "plugin" in step
    ]


@planned
def previous_stage_dir(wildcards):
    level = stage_level(wildcards)
    return stage_dir(wildcards.pair, STAGES[wildcards.pair][level - 1]) if level else ""


def previous_stage_file(name):
    """An input function: the previous stage's file ``name``; nothing for stage 0."""

    @planned
    def previous(wildcards):
        level = stage_level(wildcards)
        if level == 0:
            return []
        return f"{stage_dir(wildcards.pair, STAGES[wildcards.pair][level - 1])}/{name}"

    return previous


@planned
def pair_stats(wildcards):
    return [
        f"{stage_dir(wildcards.pair, stage)}/stats.json"
        for stage in STAGES[wildcards.pair]
    ]


def all_stage_files(name):
    return [
        f"{stage_dir(pair, stage)}/{name}" for pair in PAIRS for stage in STAGES[pair]
    ]


@planned
def pair_suggestions(wildcards):
    """What a pair's page shows to try next: every stage's where it shows the stage figures
    (plots.pairs, or its stages.html), else its last stage's where suggest_pairs selects it: in
    a drive of thousands of pairs every stage's of every pair would be most of the study's work,
    the next step is the last stage's, and the study's next steps need a spread of pairs.
    """
    stages = STAGES[wildcards.pair]
    if page_has_figures(wildcards):
        shown = stages
    else:
        shown = stages[-1:] if wildcards.pair in SUGGEST_PAIRS else []
    return [
        f"{stage_dir(wildcards.pair, stage)}/suggestions.parquet" for stage in shown
    ]


@planned
def suggest_priority(wildcards):
    """A plotted pair's suggest jobs after the other jobs, its earlier stages first: a stage whose
    hypothesis changed no point then finds the stage before's rows written and reuses them
    (lidarfield.analysis.suggest) instead of running the same candidates beside it. A priority
    is no rerun trigger: choosing plots.pairs replans no job."""
    return -stage_level(wildcards) if wildcards.pair in PLOT_PAIRS else 0


@planned
def last_stage_suggestions(wildcards):
    """The study's next steps: the suggestions of each pair of suggest_pairs at its last stage."""
    return [
        f"{stage_dir(pair, STAGES[pair][-1])}/suggestions.parquet"
        for pair in PAIRS
        if pair in SUGGEST_PAIRS
    ]


@planned
def study_dir(wildcards, input):
    """The study level's folder, from its voxels table among the inputs."""
    return str(Path(input.voxels).parent)


@planned
def pair_stage_dirs(wildcards):
    return [stage_dir(wildcards.pair, stage) for stage in STAGES[wildcards.pair]]


@planned
def page_has_figures(wildcards):
    """A pair's report.html shows its pair and stage figures when plots.pairs selects it; its
    stages.html (asked for on demand) always does."""
    return wildcards.page == "stages" or wildcards.pair in PLOT_PAIRS


@planned
def pair_page_pair_figures(wildcards):
    if not page_has_figures(wildcards):
        return []
    return f"{RESULTS}/{wildcards.pair}/figures"


@planned
def pair_page_stage_figures(wildcards):
    if not page_has_figures(wildcards):
        return []
    return [f"{d}/figures" for d in pair_stage_dirs(wildcards)]


@planned
def figures_flag(wildcards):
    return "--figures" if page_has_figures(wildcards) else "--no-figures"


@planned
def on_demand_page(wildcards):
    return f"{RESULTS}/{wildcards.pair}/stages.html"


@planned
def rematch_files(wildcards=None):
    """The stages' rematch tables, when the study asks for rematching (else none: no job)."""
    if not STUDY.rematch:
        return []
    if wildcards is not None and "pair" in wildcards.keys():
        return [
            f"{stage_dir(wildcards.pair, s)}/rematch.parquet"
            for s in STAGES[wildcards.pair]
        ]
    return all_stage_files("rematch.parquet")


GRID = canonical_json(STUDY.grid_section)
REMATCH = canonical_json(STUDY.rematch)
PLOTS = canonical_json(figure_settings(STUDY.config["plots"]))


# explain (workflow/rules/explain.smk): the config's suggest list (null: the default
# candidates) and explain settings.
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


# The pair explorer (explorer.smk): its point budget, a stage's own changes, a page's files.
EXPLORER_POINTS = config["report"]["explorer_points"]


@planned
def stage_own_changes(wildcards):
    """What stage k itself changed: none for stage 0."""
    if stage_level(wildcards) == 0:
        return []
    return f"{this_stage_dir(wildcards)}/changes.parquet"


@planned
def pair_page_explorer(wildcards):
    if not page_has_figures(wildcards):
        return []
    folder = f"{RESULTS}/{wildcards.pair}/explorer"
    stages = [f"{folder}/{stage}.js" for stage in STAGES[wildcards.pair]]
    return [
        f"{folder}/points.js",
        f"{folder}/rest.js",
        *stages,
        f"{RESULTS}/assets/explorer.js",
    ]
