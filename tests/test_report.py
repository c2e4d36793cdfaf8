"""The study report, the comparison of two studies and their CLIs, on synthetic study folders."""

from __future__ import annotations

import json
import re
import shutil

import pandas as pd
import pytest

from lidarfield.cli import main
from lidarfield.errors import InputError
from lidarfield.plots import plot_pair, plot_stage
from lidarfield.plots.synthetic import write_summary, write_synthetic_study
from lidarfield.report import compare_studies, discover, write_report
from lidarfield.report.html import STAGE_FIGURES

FAST = {"background_points": 2000, "dpi": 50}


@pytest.fixture(scope="module")
def study(tmp_path_factory):
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
    m = re.search(r'<p class="budget">.*?(\d+) of its (\d+) pair and stage figures are embedded .*? the other (\d+) are linked', html)
    return tuple(int(g) for g in m.groups()) if m else None


def report_bytes(path) -> int:
    return path.stat().st_size


def embedded_elements(html: str, caption_end: str) -> list[str]:
    """The embedded figure elements whose caption ends with ``caption_end``."""
    return re.findall(rf'<figure[^>]*><img [^>]*alt="[^"]*{re.escape(caption_end)}"[^>]*>.*?</figure>', html)


N_PAIR_FIGURES = 2 * 3  # two pairs, three pair figures each


def stage_figure_files(pairs) -> set:
    """The stage figures drawn for the study (which ones is plot_stage's business)."""
    files = {d / "figures" / f"{stem}.png" for dirs in pairs.values() for d in dirs for stem, _ in STAGE_FIGURES}
    return {f for f in files if f.is_file()}


def test_report_names_every_pair_and_stage_and_embeds_the_figures(study, tmp_path):
    root, pairs = study
    found, rows = discover(root)
    assert {k: [d.name for d in v] for k, v in found.items()} == {k: [d.name for d in v] for k, v in pairs.items()}
    out = write_report({"grid": {"kind": "spherical"}, "note": "<script>alert(1)</script>"}, found, rows, tmp_path / "report.html")
    html = out.read_text()
    for name, dirs in pairs.items():
        assert f"pair {name}" in html
        for d in dirs:
            assert d.name in html
    # the all-pairs plot, 2 pair figures per pair and every stage figure drawn
    assert image_count(html) == 1 + N_PAIR_FIGURES + len(stage_figure_files(pairs))
    # stage 0 has no removed_* nor before_after, stage 1 has all six: none is reported missing
    assert len(stage_figure_files(pairs)) == 2 * (3 + 6) and 'class="missing"' not in html
    assert "<script>alert(1)</script>" not in html and "&lt;script&gt;alert(1)&lt;/script&gt;" in html
    assert "<script" not in html  # one static page: no script at all
    link = re.findall(r'href="([^"#]+field_3d\.html)"', html)
    assert len(link) == 1 and (out.parent / link[0]).is_file()
    assert 'class="flag"' not in html


def test_report_shows_what_to_try_next_per_stage_and_for_the_study(study, tmp_path):
    root, pairs = study
    found, rows = discover(root)
    html = write_report({}, found, rows, tmp_path / "report.html").read_text()
    study_part = html.split("<h2>What to try next</h2>", 1)[1].split("<h2>", 1)[0]
    # Per pair, the best two candidates at its last stage (there are two candidates).
    assert study_part.count("<tr>") == 1 + 2 * 2
    for name, dirs in pairs.items():
        assert f'<td class="text">{name}</td><td class="text">{dirs[-1].name}</td><td class="text">1</td>' in study_part
    # Every stage has its own table, ranks 1 and 2 with the measured energy reduction.
    assert html.count("<b>What to try next.</b>") == sum(len(d) for d in pairs.values())
    table = pd.read_parquet(pairs["pair-00"][0] / "suggestions.parquet")
    assert list(table["rank"]) == [1, 2]
    assert f"{100 * table['energy_reduction'][0]:.1f}%" in html


def test_report_shows_only_the_figures_the_config_draws_and_flags_a_lost_one(study, tmp_path):
    root, pairs = study
    found, rows = discover(root)
    html = write_report({"plots": {"figures": ["field_top", "before_after"]}}, found, rows, tmp_path / "r.html").read_text()
    assert image_count(html) == 1 + N_PAIR_FIGURES + 2 * (1 + 2)  # stage 0: field_top; stage 1: both
    assert 'class="missing"' not in html
    lost = tmp_path / "lost"
    shutil.copytree(root, lost)
    (lost / "pair-01" / "stages" / pairs["pair-01"][1].name / "figures" / "field_top.png").unlink()
    found, rows = discover(lost)
    html = write_report({}, found, rows, tmp_path / "lost.html").read_text()
    assert len(re.findall('class="missing"', html)) == 1 and "field_top.png missing" in html


def test_report_links_3d_views_relative_to_itself(study):
    root, _ = study
    found, rows = discover(root)
    out = write_report({}, found, rows, root / "report.html")
    (link,) = re.findall(r'href="([^"#]+field_3d\.html)"', out.read_text())
    assert not link.startswith("/") and (root / link).is_file()


def test_report_flags_a_registration_that_did_not_converge(study, tmp_path):
    root, _ = study
    found, rows = discover(root)
    rows = [dict(r) for r in rows]
    rows[1]["registration_converged"] = False
    rows[2]["registration_warning"] = "fitness below 0.3"
    html = write_report({}, found, rows, tmp_path / "r.html").read_text()
    assert html.count('<tr class="flag">') == 2
    assert "registration did not converge" in html and "fitness below 0.3" in html


def test_discover_takes_the_stages_of_the_summary_only(study, tmp_path):
    root, pairs = study
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


def test_discover_reads_a_single_pair_folder_and_its_csv_summary(study, tmp_path):
    root, pairs = study
    pair_dir = tmp_path / "one"
    shutil.copytree(root / "pair-00", pair_dir)
    (pair_dir / "summary.parquet").unlink()
    found, rows = discover(pair_dir)
    assert list(found) == ["one"] and len(found["one"]) == 2
    assert rows[0]["rigid_translation_m"] == pytest.approx(json.loads((pairs["pair-00"][0] / "stats.json").read_text())["rigid_translation_m"])


def test_discover_rejects_a_folder_without_pairs(tmp_path):
    with pytest.raises(InputError, match="no pair folders"):
        discover(tmp_path)


def test_compare_shows_both_studies_with_deltas(study, tmp_path):
    root, pairs = study
    other = tmp_path / "variant"
    shutil.copytree(root / "pair-00", other / "pair-00")
    rows = [json.loads((d / "stats.json").read_text()) for d in pairs["pair-00"]]
    rows[1]["max_magnitude"] -= 0.5  # the variant's stage 1 explains more
    write_summary(other, rows)
    html = compare_studies(root, other, tmp_path / "compare.html").read_text()
    assert str(root) in html and str(other) in html
    assert "pair pair-00" in html and "pair pair-01" in html and "(only in A)" in html
    assert re.search(r'<td class="better">-0\.5</td>', html)
    assert image_count(html) == 2 + 2 * 2 + 2  # curves per pair; field_top A|B per stage of pair-00, A and missing B for pair-01


def test_cli_report_compare_and_plot(study, tmp_path, capsys):
    root, pairs = study
    assert main(["report", str(root), "--out", str(tmp_path / "r.html")]) == 0
    assert main(["compare", str(root), str(root), "--out", str(tmp_path / "c.html")]) == 0
    assert (tmp_path / "r.html").is_file() and (tmp_path / "c.html").is_file()
    empty = tmp_path / "empty-stage"
    empty.mkdir()
    assert main(["plot", str(empty), "--out", str(tmp_path / "figs")]) == 2
    err = capsys.readouterr().err
    assert "field.parquet: file not found" in err and len(err.strip().splitlines()) == 1


def test_a_large_budget_embeds_every_figure(study, tmp_path):
    root, pairs = study
    found, rows = discover(root)
    html = write_report({}, found, rows, tmp_path / "r.html", max_mb=100).read_text()
    assert image_count(html) == 1 + N_PAIR_FIGURES + len(stage_figure_files(pairs))
    # stage 0 has no removed_* nor before_after, stage 1 has all six: none is reported missing
    assert len(stage_figure_files(pairs)) == 2 * (3 + 6) and 'class="missing"' not in html
    assert figure_links(html) == [] and budget_counts(html) is None


def test_a_small_budget_embeds_the_pair_figures_and_links_the_stage_figures(study, caplog):
    root, pairs = study
    stage_files = stage_figure_files(pairs)
    found, rows = discover(root)
    full = write_report({}, found, rows, root / "full.html", max_mb=100)
    bare = write_report({}, found, rows, root / "bare.html", max_mb=1e-6)
    # Just above the page with only the pair figures: the bare page plus their embedded elements.
    pair_figures = embedded_elements(full.read_text(), "stage by stage")
    assert len(pair_figures) == N_PAIR_FIGURES
    budget = report_bytes(bare) + sum(len(f.encode()) for f in pair_figures)
    assert budget < report_bytes(full)
    with caplog.at_level("INFO", logger="lidarfield.report.html"):
        out = write_report({}, found, rows, root / "report.html", max_mb=budget / 1e6)
    html = out.read_text()
    assert report_bytes(out) <= budget
    assert image_count(html) == 1 + N_PAIR_FIGURES  # the all-pairs figure is always embedded
    links = figure_links(html)
    assert not any(link.startswith("/") for link in links)
    assert len(links) == len(stage_files) and {(root / link).resolve() for link in links} == {f.resolve() for f in stage_files}
    assert budget_counts(html) == (N_PAIR_FIGURES, N_PAIR_FIGURES + len(stage_files), len(stage_files))
    assert f"size budget of {budget / 1e6:g} MB" in html and "report.max_mb" in html and "inside its results folder" in html
    assert f"{report_bytes(out) / 1e6:.2f} MB" in caplog.text and f"{N_PAIR_FIGURES} figures embedded, {len(stage_files)} linked" in caplog.text


def test_the_next_tier_is_embedded_in_every_stage_when_it_fits_too(study):
    root, pairs = study
    found, rows = discover(root)
    full = write_report({}, found, rows, root / "full.html", max_mb=100).read_text()
    bare = write_report({}, found, rows, root / "bare.html", max_mb=1e-6)
    field_top = embedded_elements(full, ": field from above")
    assert len(field_top) == 4  # 2 pairs x 2 stages
    budget = report_bytes(bare) + sum(len(f.encode()) for f in embedded_elements(full, "stage by stage") + field_top)
    html = write_report({}, found, rows, root / "report.html", max_mb=budget / 1e6).read_text()
    assert image_count(html) == 1 + N_PAIR_FIGURES + len(field_top)
    assert embedded_elements(html, ": field from above") == field_top
    linked = {(root / link).resolve() for link in figure_links(html)}
    assert linked == {f.resolve() for f in stage_figure_files(pairs) if f.name != "field_top.png"}


def test_a_budget_too_small_for_any_figure_still_writes_the_page_with_every_figure_linked(study, caplog):
    root, pairs = study
    found, rows = discover(root)
    with caplog.at_level("WARNING", logger="lidarfield.report.html"):
        out = write_report({"grid": {"kind": "spherical"}}, found, rows, root / "tiny.html", max_mb=0.001)
    html = out.read_text()
    assert report_bytes(out) > 1000 and "over its 0.001 MB budget" in caplog.text
    assert html.rstrip().endswith("</html>") and "<table>" in html and "kind: spherical" in html
    assert image_count(html) == 1
    links = figure_links(html)
    assert len(links) == N_PAIR_FIGURES + len(stage_figure_files(pairs)) and all((root / link).is_file() for link in links)
    assert budget_counts(html) == (0, len(links), len(links))


def test_a_pair_figure_without_a_file_says_it_is_left_out(study, tmp_path):
    root, _ = study
    found, rows = discover(root)
    bare_pair = tmp_path / "pair-00"
    shutil.copytree(root / "pair-00" / "stages", bare_pair / "stages")  # no pair figures on disk
    html = write_report({}, {"pair-00": [bare_pair / "stages" / d.name for d in found["pair-00"]]}, [r for r in rows if r["pair"] == "pair-00"], tmp_path / "r.html", max_mb=0.001).read_text()
    assert html.count("not embedded (size budget) and not on disk to link") == 3  # the three pair figures


def test_cli_report_takes_its_budget_from_max_mb_or_else_the_config(study, tmp_path, capsys):
    root, _ = study
    config = tmp_path / "study.yaml"
    config.write_text("report: {max_mb: 0.001}\n")
    out = tmp_path / "r.html"
    assert main(["report", str(root), "--out", str(out), "--config", str(config)]) == 0
    assert budget_counts(out.read_text())[0] == 0
    assert main(["report", str(root), "--out", str(out), "--config", str(config), "--max-mb", "100"]) == 0
    assert budget_counts(out.read_text()) is None
    for bad in ("0", "-1", "x", "nan"):
        with pytest.raises(SystemExit):
            main(["report", str(root), "--out", str(out), "--max-mb", bad])
    assert "--max-mb: a size in MB greater than 0, not 'x'" in capsys.readouterr().err


def test_the_report_knows_every_figure_a_stage_can_have():
    from lidarfield.plots import STAGE_FIGURES as DRAWN

    assert sorted(stem for stem, _ in STAGE_FIGURES) == sorted(DRAWN)
