"""The pair explorer on a pair's page: its stages in one interactive 3-D view and a top view.

The page loads, by relative path, the viewer (``assets/explorer.js`` of the results folder, one
copy for the study: a WebGL viewer of its own, no library) and the pair's data
(``{pair}/explorer/points.js`` and one ``{stage}.js`` per stage, and ``rest.js`` when the analyst
asks for every point, see :mod:`.explorer_data`): no server, no network, and the page itself
stays small whatever the point budget.
"""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

from ..errors import InputError
from ..io.atomic import write_text
from ..storage.layout import level_of
from .explorer_data import FOLDER, POINTS, REST, write_points_scripts, write_stage_script
from .page import esc, relative_href

ASSETS = "assets"  # the results folder's shared scripts
VIEWER = "explorer.js"
OVERVIEW = "overview.js"  # the overview's table sorting and filter (lidarfield.report.study_view)
STYLE = """<style>
.explorer { margin: 0.6em 0; }
.explorer-controls { display: flex; flex-wrap: wrap; gap: 0.3em 0.8em; align-items: center; margin: 0.3em 0; }
.stage-slider { width: 16em; }
.explorer-views { display: flex; gap: 10px; }
.explorer-view { flex: 1 1 0; min-width: 0; border: 1px solid #ddd; }
.explorer-title { font-size: 0.85em; margin: 0.2em 0.4em; }
.explorer-canvas { position: relative; height: 620px; }
.explorer-canvas canvas { position: absolute; left: 0; top: 0; width: 100%; height: 100%; }
.explorer-canvas canvas.gl { cursor: grab; touch-action: none; }
.explorer-tooltip { position: absolute; pointer-events: none; background: rgba(255,255,255,0.95);
  border: 1px solid #888; padding: 2px 5px; font-size: 12px; white-space: nowrap; z-index: 2; }
.explorer-legend { display: flex; flex-wrap: wrap; gap: 0.2em 1em; align-items: center; font-size: 0.85em; }
.explorer-legend .bar { display: inline-block; width: 10em; height: 0.8em; vertical-align: middle; margin: 0 0.3em; }
.explorer-legend .swatch { display: inline-block; width: 0.8em; height: 0.8em; margin-right: 0.25em;
  vertical-align: middle; }
.selected-voxel { font-size: 0.9em; }
</style>"""


def script_source(name: str) -> str:
    """One of the report's scripts, as the package ships it."""
    return resources.files(__package__).joinpath("assets", name).read_text()


def write_script(path: str | Path) -> Path:
    """One of the report's own scripts (the explorer's or the overview's), named as shipped."""
    path = Path(path)
    if path.name not in (VIEWER, OVERVIEW):
        raise InputError(f"not one of the report's scripts ({VIEWER}, {OVERVIEW})", path)
    write_text(path, script_source(path.name))
    return path


def explorer_dir(pair_dir: Path) -> Path:
    return pair_dir / FOLDER


def stage_script(pair_dir: Path, stage_id: str) -> Path:
    return explorer_dir(pair_dir) / f"{stage_id}.js"


def points_script(pair_dir: Path) -> Path:
    return explorer_dir(pair_dir) / f"{POINTS}.js"


def rest_script(pair_dir: Path) -> Path:
    return explorer_dir(pair_dir) / f"{REST}.js"


def stage_label(stage_id: str) -> str:
    """``02 field_of_view`` for ``02-field_of_view-1a2b3c4d``."""
    level, _, rest = stage_id.partition("-")
    return f"{level} {rest.rsplit('-', 1)[0]}" if level_of(stage_id) is not None else stage_id


def explorer_scripts(assets: Path, out_dir: Path) -> list[str]:
    """The viewer's scripts (in ``assets``), loaded once by a page in ``out_dir``, and its style."""
    return [STYLE, f'<script src="{esc(relative_href(assets / VIEWER, out_dir))}"></script>']


def explorer_div(name: str, stage_dirs: list[Path], out_dir: Path, how: str, link: str = "") -> str:
    """One explorer of the pair of ``stage_dirs`` (``{pair}/stages/{stage}``) on a page in
    ``out_dir``: it loads the pair's data files; ``how``: what makes them when they are not
    written (HTML); explorers of one ``link`` share their camera and stage."""
    pair_dir = stage_dirs[0].parent.parent
    data = [points_script(pair_dir), *(stage_script(pair_dir, d.name) for d in stage_dirs)]
    spec = {
        "pair": name,
        "stages": [{"id": d.name, "label": stage_label(d.name)} for d in stage_dirs],
        "scripts": [relative_href(path, out_dir) for path in data],
        "rest": relative_href(rest_script(pair_dir), out_dir),
        "how": how,
    }
    # "</" would end the JSON's script element early: JSON allows "<\/" for it
    spec_json = json.dumps(spec).replace("</", "<\\/")
    linked = f' data-link="{esc(link)}"' if link else ""
    return f'<div class="explorer"{linked}><script type="application/json">{spec_json}</script></div>'


EXPLAINER = (
    '<p class="note">The pair at every stage: drag the slider to step through the hypotheses; the cameras and '
    "the selected voxel stay. Points are grey (cloud 1) and blue-grey (cloud 2); the points a stage removed are "
    "in that stage's colour, where they were when it removed them; a correcting stage's moves are arrows from "
    "before to after. 3-D view: drag to turn, shift-drag (or the right button) to pan, the wheel to zoom; top "
    "view: drag to pan, the wheel to zoom; double-click resets a view. Hover a vector for its voxel; click it to "
    "select it. Each view's PNG button saves what it shows.</p>"
)


def explorer_parts(name: str, stage_dirs: list[Path], out_dir: Path, assets: Path, how: str) -> list[str]:
    """The explorer's section of a pair's page in ``out_dir``, its viewer's scripts in ``assets``."""
    return [
        "<h2>Explorer</h2>",
        EXPLAINER,
        *explorer_scripts(assets, out_dir),
        explorer_div(name, stage_dirs, out_dir, how),
    ]


def write_explorer_data(pair_dir: Path, stage_dirs: list[Path], budget: int) -> list[Path]:
    """A pair's explorer files, as the workflow's jobs write them (``lidarfield report`` and the tests)."""
    registered = pair_dir / "registered.parquet"
    written = write_points_scripts(registered, budget, points_script(pair_dir), rest_script(pair_dir))
    for d in stage_dirs:
        changes = d / "changes.parquet"
        written.append(
            write_stage_script(
                registered,
                d / "field.parquet",
                changes if changes.is_file() else None,
                budget,
                stage_script(pair_dir, d.name),
            )
        )
    return written


def write_assets(assets: Path) -> list[Path]:
    """The report's scripts in ``assets``."""
    return [write_script(assets / name) for name in (VIEWER, OVERVIEW)]
