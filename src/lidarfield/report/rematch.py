"""The report's pieces on rematching: per pair, the pose error per stage and method; for the
study, what each hypothesis does to each method's error, with the hypotheses that shrink the
field but make matching worse shown as such."""

from __future__ import annotations

from ..analysis.rematch import METHOD_COLUMNS, method_rows
from ..plots.output import png_bytes
from ..plots.rematch import ABSOLUTE_CHANGE_M, RELATIVE_CHANGE, hypothesis_effects, study_rematch_figure
from .page import image, table


def rematched_methods(rows: list[dict]) -> list[str]:
    """The methods the summary rows carry rematch columns for, in their order."""
    return list(dict.fromkeys(r["method"] for r in method_rows(rows)))


def pair_rematch_table(rows: list[dict]) -> str:
    """One pair's stages x methods: median and 90th percentile errors, converged share ('' without rematching)."""
    rematched = method_rows(rows)
    if not rematched:
        return ""
    body = [[r[c] for c in METHOD_COLUMNS] for r in rematched]
    classes = ["flag" if (r["converged"] or 0) < 1 else "" for r in rematched]
    note = (
        '<p class="note">Rematching (rows in red: some trials did not converge). Errors against the reference pose.</p>'
    )
    return note + table(list(METHOD_COLUMNS), body, classes, text_columns=2)


def study_rematch_parts(rows: list[dict], dpi: int) -> list[str]:
    """The study's rematching section ([] without rematching): the effects figure and table."""
    methods = rematched_methods(rows)
    if not methods:
        return []
    effects = hypothesis_effects(rows, methods)
    headers = [
        "stage",
        "hypothesis",
        "method",
        "pairs",
        "Δ field p95 (m)",
        "Δ median translation error (cm)",
        "relative Δ (%)",
        "Δ median rotation error (deg)",
        "matching",
    ]
    body, classes = [], []
    for e in effects:
        verdict = "field shrinks, matching worse" if e["worse_matching"] else e["verdict"]
        # rounded to what the errors can mean (0.01 mm, 0.1 %, 1e-4 deg): not 1.6e-14 cm; + 0.0 turns -0 into 0
        body.append(
            [
                f"{e['level']:02d}",
                e["hypothesis"],
                e["method"],
                e["pairs"],
                e["field_p95_change_m"],
                round(e["translation_change_m"] * 100, 3) + 0.0,
                round(e["translation_relative_change"] * 100, 1) + 0.0,
                round(e["rotation_change_deg"], 4) + 0.0,
                verdict,
            ]
        )
        classes.append("flag" if e["worse_matching"] else "")
    return [
        "<h2>Rematching: does each hypothesis help scan matching?</h2>",
        '<p class="note">Every stage registered again with each method from seeded starts about the reference '
        "pose (the truth when known, else the study's registration). Changes from stage k-1 to k, median over "
        f"pairs; negative = smaller; a change within {RELATIVE_CHANGE:.0%} of the error or below "
        f"{ABSOLUTE_CHANGE_M * 1000:g} mm is no clear change. Rows in red: "
        "the hypothesis shrinks the field but makes that method's matching worse.</p>",
        image(
            png_bytes(study_rematch_figure(rows, methods, dpi), dpi),
            "change in median pose error per hypothesis and method",
        ),
        table(headers, body, classes, text_columns=3),
    ]
