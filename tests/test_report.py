"""The study report, the comparison of two studies and their CLIs, on synthetic study folders."""

from __future__ import annotations

import json
import re
import shutil

import pytest

from lidarfield.cli import main
from lidarfield.errors import InputError
from lidarfield.plots import plot_stage
from lidarfield.plots.synthetic import write_summary, write_synthetic_study
from lidarfield.report import compare_studies, discover, write_report

FAST = {"background_points": 2000, "dpi": 50}


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """Two pairs of two stages each, plotted (the 3-D view only for pair-00's last stage)."""
    root = tmp_path_factory.mktemp("results")
    pairs = write_synthetic_study(root, n_pairs=2, levels=2, n=6000)
    for name, dirs in pairs.items():
        for i, d in enumerate(dirs):
            interactive = name == "pair-00" and i == len(dirs) - 1
            plot_stage(d, dirs[i - 1] if i else None, d / "figures", {**FAST, "interactive": interactive})
    return root, pairs


def image_count(html: str) -> int:
    return len(re.findall(r'src="data:image/png;base64,', html))


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
    # all-pairs plot + per pair (2 pair figures + 5 figures of stage 0 + 6 of stage 1)
    assert image_count(html) == 1 + 2 * (2 + 5 + 6)
    assert "<script>alert(1)</script>" not in html and "&lt;script&gt;alert(1)&lt;/script&gt;" in html
    assert "<script" not in html  # one static page: no script at all
    link = re.findall(r'href="([^"#]+field_3d\.html)"', html)
    assert len(link) == 1 and (out.parent / link[0]).is_file()
    assert 'class="flag"' not in html


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
