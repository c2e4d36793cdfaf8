"""The study report, the comparison of two studies and their CLIs, on synthetic study folders."""

from __future__ import annotations

import json
import os
import re
import shutil

import pandas as pd
import pytest

from helpers.synthetic_study import write_summary, write_synthetic_study
from lidarfield.cli import main
from lidarfield.errors import InputError
from lidarfield.plots import plot_pair, plot_stage
from lidarfield.report import compare_studies, discover, write_pair_page, write_report
from lidarfield.report.pair_page import STAGE_FIGURE_CAPTIONS

FAST = {"background_points": 2000, "dpi": 50}


@pytest.fixture(scope="module")
def plotted_study(tmp_path_factory):
    """Two pairs of two stages each, plotted (the 3-D view only for pair-00's last stage), with
    their pair figures."""
    root = tmp_path_factory.mktemp("results")
    pairs = write_synthetic_study(root, n_pairs=2, levels=2, n=6000)
    for name, dirs in pairs.items():
        for i, d in enumerate(dirs):
            interactive = name == "pair-00" and i == len(dirs) - 1
            plot_stage(d, dirs[i - 1] if i else None, d / "figures", {**FAST, "interactive": interactive})
        plot_pair([json.loads((d / "stats.json").read_text()) for d in dirs], root / name / "figures", FAST)
    return root, pairs


def image_count(html: str) -> int:
    return len(re.findall(r'src="data:image/png;base64,', html))


def figure_links(html: str) -> list[str]:
    """The targets of the figures linked instead of embedded."""
    return re.findall(r'<figure class="linked">.*?<a href="([^"]+)">open figure</a></figure>', html)


def budget_counts(html: str) -> tuple[int, int, int] | None:
    """(embedded, all, linked) figures as the page's size-budget note says them; None without a note."""
    m = re.search(
        r'<p class="budget">.*?(\d+) of its (\d+) pair and stage figures are embedded .*? the other (\d+) are linked',
        html,
    )
    return tuple(int(g) for g in m.groups()) if m else None


def report_bytes(path) -> int:
    return path.stat().st_size


def embedded_elements(html: str, caption_end: str) -> list[str]:
    """The embedded figure elements whose caption ends with ``caption_end``."""
    return re.findall(rf'<figure[^>]*><img [^>]*alt="[^"]*{re.escape(caption_end)}"[^>]*>.*?</figure>', html)


N_PAIR_FIGURES = 3  # a pair page's stage-by-stage figures
N_STUDY_FIGURES = 2  # hypotheses, all pairs (the heat map is a grid of links, the polar maps SVG)


def stage_figure_files(pairs) -> set:
    """The stage figures drawn for the study (which ones is plot_stage's business)."""
    files = {
        d / "figures" / f"{stem}.png" for dirs in pairs.values() for d in dirs for stem, _ in STAGE_FIGURE_CAPTIONS
    }
    return {f for f in files if f.is_file()}


def pair_page(root, name: str) -> str:
    return (root / name / "report.html").read_text()


def test_report_writes_an_overview_and_a_page_per_pair(plotted_study, tmp_path):
    root, pairs = plotted_study
    found, rows = discover(root)
    assert {k: [d.name for d in v] for k, v in found.items()} == {k: [d.name for d in v] for k, v in pairs.items()}
    out = write_report(
        {"grid": {"kind": "spherical"}, "note": "<script>alert(1)</script>"}, found, rows, tmp_path / "report.html"
    )
    html = out.read_text()
    assert image_count(html) == N_STUDY_FIGURES  # the study level only: each pair's figures are on its page
    assert html.index("The study level") < html.index("Pairs ranked") < html.index("<details><summary>the config")
    assert "<script>alert(1)</script>" not in html and "&lt;script&gt;alert(1)&lt;/script&gt;" in html
    # no inline script: only the report's own, by relative path
    assert re.findall(r"<script[^>]*>", html) == ['<script src="assets/overview.js"></script>'[:-9]]
    # The ranking gives each pair's last-stage verdict and significant voxels.
    ranking = html.split("Pairs ranked", 1)[1].split("</table>", 1)[0]
    assert "<th>verdict</th>" in ranking
    for r in rows:
        if r["level"] == max(x["level"] for x in rows if x["pair"] == r["pair"]):
            assert f"<td>{r['verdict']}</td>" in ranking and f"<td>{r['voxels_significant']}</td>" in ranking
    for name, dirs in pairs.items():
        assert f'<a href="{name}/report.html">{name}</a>' in html
        page = pair_page(tmp_path, name)
        assert f"<h1>pair {name}</h1>" in page and '<a href="../report.html">' in page
        for d in dirs:
            assert d.name in page
        # 2 pair figures and every stage figure drawn: stage 0 has 3, stage 1 all six
        assert image_count(page) == N_PAIR_FIGURES + 3 + 6 and 'class="missing"' not in page
        assert 'class="flag"' not in page
        # the viewer's scripts by relative path; its spec (JSON, not a script) names the pair's data files
        assert not (tmp_path / "assets" / "plotly.min.js").exists()  # the explorer draws with WebGL itself
        scripts = re.findall(r"<script([^>]*)>", page)
        assert scripts == [' src="../assets/explorer.js"', ' type="application/json"']
        spec = json.loads(re.search(r'<script type="application/json">(.*?)</script>', page).group(1))
        stems = ["points", *(d.name for d in dirs)]
        assert [os.path.normpath(tmp_path / name / s) for s in spec["scripts"]] == [
            str(root / name / "explorer" / f"{stem}.js") for stem in stems
        ]
        assert os.path.normpath(tmp_path / name / spec["rest"]) == str(root / name / "explorer" / "rest.js")
    link = re.findall(r'href="([^"#]+field_3d\.html)"', pair_page(tmp_path, "pair-00"))
    assert len(link) == 1 and (tmp_path / "pair-00" / link[0]).is_file()


def test_report_shows_what_to_try_next_per_stage_and_for_the_study(plotted_study, tmp_path):
    root, pairs = plotted_study
    found, rows = discover(root)
    html = write_report({}, found, rows, tmp_path / "report.html").read_text()
    study_part = html.split("<h2>What to try next</h2>", 1)[1].split("<h2>", 1)[0]
    # Per pair, the best two candidates at its last stage (there are two candidates).
    assert study_part.count("<tr>") == 1 + 2 * 2
    for name, dirs in pairs.items():
        assert f'<td class="text">{name}</td><td class="text">{dirs[-1].name}</td><td class="text">1</td>' in study_part
    # Every stage has its own table on its pair's page, ranks 1 and 2 with the measured energy reduction.
    for name, dirs in pairs.items():
        assert pair_page(tmp_path, name).count("<b>What to try next.</b>") == len(dirs)
    table = pd.read_parquet(pairs["pair-00"][0] / "suggestions.parquet")
    assert list(table["rank"]) == [1, 2]
    assert f"{100 * table['energy_reduction'][0]:.1f}%" in pair_page(tmp_path, "pair-00")


def test_pair_page_shows_only_the_figures_the_config_draws_and_flags_a_lost_one(plotted_study, tmp_path):
    root, pairs = plotted_study
    found, rows = discover(root)
    write_report({"plots": {"figures": ["field_top", "before_after"]}}, found, rows, tmp_path / "r.html")
    assert image_count(pair_page(tmp_path, "pair-01")) == N_PAIR_FIGURES + 1 + 2  # stage 0: field_top; stage 1: both
    assert 'class="missing"' not in pair_page(tmp_path, "pair-01")
    lost = tmp_path / "lost"
    shutil.copytree(root, lost)
    (lost / "pair-01" / "stages" / pairs["pair-01"][1].name / "figures" / "field_top.png").unlink()
    found, rows = discover(lost)
    write_report({}, found, rows, lost / "report.html")
    page = pair_page(lost, "pair-01")
    assert len(re.findall('class="missing"', page)) == 1 and "field_top.png missing" in page
    assert 'class="missing"' not in pair_page(lost, "pair-00")


def test_a_pair_without_figures_says_how_to_draw_them(plotted_study, tmp_path):
    root, pairs = plotted_study
    found, rows = discover(root)
    rows = [r for r in rows if r["pair"] == "pair-01"]
    out = write_pair_page(
        "pair-01",
        found["pair-01"],
        rows,
        tmp_path / "pair-01" / "report.html",
        with_figures=False,
        on_demand="results/pair-01/stages.html",
    )
    page = out.read_text()
    assert image_count(page) == 0 and 'class="missing"' not in page
    assert "snakemake --cores 2 results/pair-01/stages.html" in page and "plots.pairs" in page


def test_a_pair_page_shows_what_to_try_next_only_for_the_stages_it_was_given(plotted_study, tmp_path):
    """A workflow page shows the suggestions its job was given (suggest_pairs), never a file of
    another run: every stage's file exists here, yet only the named stages' tables show."""
    root, pairs = plotted_study
    found, rows = discover(root)
    rows = [r for r in rows if r["pair"] == "pair-01"]
    dirs = found["pair-01"]

    def page(suggested: set[str]) -> str:
        out = tmp_path / "pair-01" / "report.html"
        return write_pair_page(
            "pair-01", dirs, rows, out, with_figures=False, on_demand="x/stages.html", suggested=suggested
        ).read_text()

    last = page({dirs[-1].name})
    assert last.count("<b>What to try next.</b>") == 1 and "before the last" in last and "suggest_pairs" not in last
    none = page(set())
    assert none.count("<b>What to try next.</b>") == 0 and "suggest_pairs</code> leaves it out" in none
    assert 'class="missing"' not in none  # not computed on purpose: a note, not a missing file


def test_the_overview_says_how_many_pairs_have_next_steps(plotted_study, tmp_path):
    from lidarfield.report import write_overview
    from lidarfield.study.tables import compute_study_tables

    root, pairs = plotted_study
    found, rows = discover(root)
    tables = compute_study_tables(found, rows)
    one = {"pair-00": found["pair-00"][-1]}
    html = write_overview({}, tables, tmp_path / "report.html", last_stages=one).read_text()
    part = html.split("<h2>What to try next</h2>", 1)[1].split("<h2>", 1)[0]
    assert "computed for 1 of the study&#x27;s 2 pairs" in part or "computed for 1 of the study's 2 pairs" in part
    assert "pair-01" not in part and "pair-00" in part


def test_report_links_3d_views_relative_to_itself(plotted_study):
    root, _ = plotted_study
    found, rows = discover(root)
    write_report({}, found, rows, root / "report.html")
    (link,) = re.findall(r'href="([^"#]+field_3d\.html)"', pair_page(root, "pair-00"))
    assert not link.startswith("/") and (root / "pair-00" / link).is_file()


def test_report_flags_a_registration_that_did_not_converge(plotted_study, tmp_path):
    root, _ = plotted_study
    found, rows = discover(root)
    rows = [dict(r) for r in rows]
    last = [i for i, r in enumerate(rows) if r["pair"] == "pair-01"][-1]
    rows[last]["registration_converged"] = False
    rows[0]["registration_warning"] = "fitness below 0.3"
    html = write_report({}, found, rows, tmp_path / "r.html").read_text()
    assert html.count('<tr class="flag">') == 1 and "registration did not converge" in html  # the ranking: last stages
    assert pair_page(tmp_path, "pair-01").count('<tr class="flag">') == 1
    assert pair_page(tmp_path, "pair-00").count('<tr class="flag">') == 1 and "fitness below 0.3" in pair_page(
        tmp_path, "pair-00"
    )


def test_pair_page_states_the_findings_and_flags_their_stages(plotted_study, tmp_path):
    root, pairs = plotted_study
    found, rows = discover(root)
    pair = rows[0]["pair"]
    rows = [dict(r) for r in rows if r["pair"] == pair]
    assert "<h2>Findings</h2>" not in write_pair_page(pair, found[pair], rows, tmp_path / "clean.html").read_text()
    for r in rows:
        r["sensor_warning"] = "scan 1: 54.5% of the points do not fit sensor model 'os1-128'"
    rows[1].update(removed1=600, n1=400, field_warning="no valid voxel: cloud 2 has no point left")
    html = write_pair_page(pair, found[pair], rows, tmp_path / "r.html").read_text()
    findings = html.split("<h2>Findings</h2>", 1)[1].split("</ul>", 1)[0]
    assert findings.count("<li>") == 3  # the sensor once for the pair, two for the stage
    assert f"pair {pair}: scan 1: 54.5% of the points do not fit sensor model &#x27;os1-128&#x27;" in findings
    assert "removed 60% of cloud 1 (600 of 1000 points)" in findings and "no valid voxel" in findings
    assert html.count('<tr class="flag">') == 1


def test_discover_takes_the_stages_of_the_summary_only(plotted_study, tmp_path):
    root, pairs = plotted_study
    copy = tmp_path / "results"
    shutil.copytree(root / "pair-01", copy / "pair-01")
    stale = copy / "pair-01" / "stages" / "01-ego_vehicle-deadbeef"  # an older variant's stage
    shutil.copytree(pairs["pair-01"][1], stale)
    found, rows = discover(copy)
    assert [d.name for d in found["pair-01"]] == [d.name for d in pairs["pair-01"]]
    (copy / "pair-01" / "summary.parquet").unlink()
    (copy / "pair-01" / "summary.csv").unlink()
    found, rows = discover(copy)  # without a summary: every stage folder, from its stats.json
    assert len(found["pair-01"]) == 3 and len(rows) == 3


def test_discover_reads_a_single_pair_folder_and_its_csv_summary(plotted_study, tmp_path):
    root, pairs = plotted_study
    pair_dir = tmp_path / "one"
    shutil.copytree(root / "pair-00", pair_dir)
    (pair_dir / "summary.parquet").unlink()
    found, rows = discover(pair_dir)
    assert list(found) == ["one"] and len(found["one"]) == 2
    assert rows[0]["rigid_translation_m"] == pytest.approx(
        json.loads((pairs["pair-00"][0] / "stats.json").read_text())["rigid_translation_m"]
    )


def test_discover_rejects_a_folder_without_pairs(tmp_path):
    with pytest.raises(InputError, match="no pair folders"):
        discover(tmp_path)


def test_compare_shows_both_studies_with_deltas(plotted_study, tmp_path):
    root, pairs = plotted_study
    other = tmp_path / "variant"
    shutil.copytree(root / "pair-00", other / "pair-00")
    rows = [json.loads((d / "stats.json").read_text()) for d in pairs["pair-00"]]
    rows[1]["max_magnitude"] -= 0.5  # the variant's stage 1 explains more
    write_summary(other, rows)
    html = compare_studies(root, other, tmp_path / "compare.html").read_text()
    assert str(root) in html and str(other) in html
    assert "pair pair-00" in html and "pair pair-01" in html and "(only in A)" in html
    assert re.search(r'<td class="better">-0\.5</td>', html)
    assert (
        image_count(html) == 2 + 2 * 2 + 2
    )  # curves per pair; field_top A|B per stage of pair-00, A and missing B for pair-01


def test_cli_report_compare_and_plot(plotted_study, tmp_path, capsys):
    root, pairs = plotted_study
    assert main(["report", str(root), "--out", str(tmp_path / "r.html")]) == 0
    assert main(["compare", str(root), str(root), "--out", str(tmp_path / "c.html")]) == 0
    assert (tmp_path / "r.html").is_file() and (tmp_path / "c.html").is_file()
    empty = tmp_path / "empty-stage"
    empty.mkdir()
    assert main(["plot", str(empty), "--out", str(tmp_path / "figs")]) == 2
    err = capsys.readouterr().err
    assert "field.parquet: file not found" in err and len(err.strip().splitlines()) == 1


def write_page(found, rows, out, max_mb):
    """pair-00's page within ``max_mb``."""
    return write_pair_page("pair-00", found["pair-00"], [r for r in rows if r["pair"] == "pair-00"], out, max_mb=max_mb)


def test_a_large_budget_embeds_every_figure(plotted_study, tmp_path):
    root, pairs = plotted_study
    found, rows = discover(root)
    html = write_page(found, rows, tmp_path / "r.html", max_mb=100).read_text()
    stage_files = stage_figure_files({"pair-00": pairs["pair-00"]})
    assert image_count(html) == N_PAIR_FIGURES + len(stage_files)
    # stage 0 has no removed_* nor before_after, stage 1 has all six: none is reported missing
    assert len(stage_files) == 3 + 6 and 'class="missing"' not in html
    assert figure_links(html) == [] and budget_counts(html) is None


def test_a_small_budget_embeds_the_pair_figures_and_links_the_stage_figures(plotted_study, caplog):
    root, pairs = plotted_study
    stage_files = stage_figure_files({"pair-00": pairs["pair-00"]})
    found, rows = discover(root)
    out_dir = root / "pair-00"
    full = write_page(found, rows, out_dir / "full.html", max_mb=100)
    bare = write_page(found, rows, out_dir / "bare.html", max_mb=1e-6)
    # Just above the page with only the pair figures: the bare page plus their embedded elements.
    pair_figures = embedded_elements(full.read_text(), "stage by stage")
    assert len(pair_figures) == N_PAIR_FIGURES
    budget = report_bytes(bare) + sum(len(f.encode()) for f in pair_figures)
    assert budget < report_bytes(full)
    with caplog.at_level("INFO", logger="lidarfield.report.budget"):
        out = write_page(found, rows, out_dir / "report.html", max_mb=budget / 1e6)
    html = out.read_text()
    assert report_bytes(out) <= budget
    assert image_count(html) == N_PAIR_FIGURES
    links = figure_links(html)
    assert not any(link.startswith("/") for link in links)
    assert len(links) == len(stage_files) and {(out_dir / link).resolve() for link in links} == {
        f.resolve() for f in stage_files
    }
    assert budget_counts(html) == (N_PAIR_FIGURES, N_PAIR_FIGURES + len(stage_files), len(stage_files))
    assert (
        f"size budget of {budget / 1e6:g} MB" in html
        and "report.max_mb" in html
        and "inside its results folder" in html
    )
    assert (
        f"{report_bytes(out) / 1e6:.2f} MB" in caplog.text
        and f"{N_PAIR_FIGURES} figures embedded, {len(stage_files)} linked" in caplog.text
    )


def test_the_next_tier_is_embedded_in_every_stage_when_it_fits_too(plotted_study):
    root, pairs = plotted_study
    found, rows = discover(root)
    out_dir = root / "pair-00"
    full = write_page(found, rows, out_dir / "full.html", max_mb=100).read_text()
    bare = write_page(found, rows, out_dir / "bare.html", max_mb=1e-6)
    field_top = embedded_elements(full, ": field from above")
    assert len(field_top) == 2  # 2 stages
    budget = report_bytes(bare) + sum(len(f.encode()) for f in embedded_elements(full, "stage by stage") + field_top)
    html = write_page(found, rows, out_dir / "report.html", max_mb=budget / 1e6).read_text()
    assert image_count(html) == N_PAIR_FIGURES + len(field_top)
    assert embedded_elements(html, ": field from above") == field_top
    linked = {(out_dir / link).resolve() for link in figure_links(html)}
    assert linked == {
        f.resolve() for f in stage_figure_files({"pair-00": pairs["pair-00"]}) if f.name != "field_top.png"
    }


def test_a_budget_too_small_for_any_figure_still_writes_the_page_with_every_figure_linked(plotted_study, caplog):
    root, pairs = plotted_study
    found, rows = discover(root)
    out_dir = root / "pair-00"
    with caplog.at_level("WARNING", logger="lidarfield.report.budget"):
        out = write_page(found, rows, out_dir / "tiny.html", max_mb=0.001)
    html = out.read_text()
    assert report_bytes(out) > 1000 and "over its 0.001 MB budget" in caplog.text
    assert html.rstrip().endswith("</html>") and "<table>" in html
    assert image_count(html) == 0
    links = figure_links(html)
    assert len(links) == N_PAIR_FIGURES + len(stage_figure_files({"pair-00": pairs["pair-00"]}))
    assert all((out_dir / link).is_file() for link in links)
    assert budget_counts(html) == (0, len(links), len(links))


def test_a_pair_figure_without_a_file_says_it_is_left_out(plotted_study, tmp_path):
    root, _ = plotted_study
    found, rows = discover(root)
    bare_pair = tmp_path / "pair-00"
    shutil.copytree(root / "pair-00" / "stages", bare_pair / "stages")  # no pair figures on disk
    html = write_pair_page(
        "pair-00",
        [bare_pair / "stages" / d.name for d in found["pair-00"]],
        [r for r in rows if r["pair"] == "pair-00"],
        tmp_path / "r.html",
        max_mb=0.001,
    ).read_text()
    assert html.count("not embedded (size budget) and not on disk to link") == 3  # the three pair figures


def test_cli_report_takes_its_budget_from_max_mb_or_else_the_config(plotted_study, tmp_path, capsys):
    root, _ = plotted_study
    config = tmp_path / "study.yaml"
    config.write_text("report: {max_mb: 0.001}\n")
    out = tmp_path / "r.html"
    assert main(["report", str(root), "--out", str(out), "--config", str(config)]) == 0
    assert budget_counts(pair_page(tmp_path, "pair-00"))[0] == 0
    assert main(["report", str(root), "--out", str(out), "--config", str(config), "--max-mb", "100"]) == 0
    assert budget_counts(pair_page(tmp_path, "pair-00")) is None
    for bad in ("0", "-1", "x", "nan"):
        with pytest.raises(SystemExit):
            main(["report", str(root), "--out", str(out), "--max-mb", bad])
    assert "--max-mb: a size in MB greater than 0, not 'x'" in capsys.readouterr().err


def test_the_report_knows_every_figure_a_stage_can_have():
    from lidarfield.plots import STAGE_FIGURES

    assert sorted(stem for stem, _ in STAGE_FIGURE_CAPTIONS) == sorted(STAGE_FIGURES)


def test_an_embedded_copy_is_the_figure_scaled_to_the_page_in_256_colours(plotted_study):
    """compact_png: a wide figure comes out EMBED_MAX_WIDTH wide, same aspect, a palette image
    whose colours stay those of the figure; an RGBA file of the same pixels gives the same copy."""
    import io

    import numpy as np
    from PIL import Image

    from lidarfield.plots.png import EMBED_MAX_WIDTH, compact_png

    _, pairs = plotted_study
    wide = np.asarray(Image.open(pairs["pair-00"][1] / "figures" / "before_after.png").convert("RGB"))
    wide = np.tile(wide, (1, 3, 1))  # wider than a page at any test dpi
    as_png = {}
    for mode in ("RGB", "RGBA"):
        buf = io.BytesIO()
        Image.fromarray(wide).convert(mode).save(buf, format="PNG")
        as_png[mode] = compact_png(buf.getvalue())
    assert as_png["RGB"] == as_png["RGBA"]
    with Image.open(io.BytesIO(as_png["RGB"])) as im:
        assert im.mode == "P" and len(im.getcolors(256)) <= 256
        assert im.width == EMBED_MAX_WIDTH and im.height == round(wide.shape[0] * EMBED_MAX_WIDTH / wide.shape[1])
        copy = np.asarray(im.convert("RGB"), dtype=np.float64)
    scaled = np.asarray(Image.fromarray(wide).resize(im.size, Image.Resampling.LANCZOS), dtype=np.float64)
    assert np.abs(copy - scaled).mean() < 2.0  # a palette of the figure's colours, not a banded one
    assert len(as_png["RGB"]) < wide.nbytes / 20
