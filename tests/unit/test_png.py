"""The figures' own PNG writer against matplotlib's savefig (the reference): same pixels."""

from __future__ import annotations

import io

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from PIL import Image  # noqa: E402

from lidarfield.plots.png import encode_png, figure_png, pixel_image  # noqa: E402


def busy_figure(transparent: bool):
    """Text, a colour bar, lines and semi-transparent points: what a stage figure holds."""
    fig = plt.figure(figsize=(4.0, 3.0), dpi=72)
    if transparent:
        fig.patch.set_alpha(0.0)
    ax = fig.add_subplot()
    rng = np.random.default_rng(0)
    points = ax.scatter(*rng.normal(size=(2, 500)), c=rng.random(500), s=4, alpha=0.4)
    ax.plot([-2, 2], [-1, 1], lw=1.5)
    ax.set_title("a title · 0.913 m")
    fig.colorbar(points, ax=ax, label="magnitude (m)")
    return fig


def savefig_pixels(fig, dpi: float) -> tuple[np.ndarray, tuple[float, float]]:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    with Image.open(buf) as im:
        return np.asarray(im.convert("RGBA")), im.info["dpi"]


@pytest.mark.parametrize("transparent", [False, True])
def test_the_png_holds_the_pixels_savefig_writes(transparent):
    fig = busy_figure(transparent)
    expected, expected_dpi = savefig_pixels(fig, 90)
    png = figure_png(fig, 90)  # a dpi other than the figure's own, as savefig allows
    plt.close(fig)
    with Image.open(io.BytesIO(png)) as im:
        im.verify()
    with Image.open(io.BytesIO(png)) as im:
        assert im.mode == ("RGBA" if transparent else "RGB")  # alpha only where a pixel needs it
        assert im.size == (360, 270)
        assert im.info["dpi"] == pytest.approx(expected_dpi)
        assert np.array_equal(np.asarray(im.convert("RGBA")), expected)
    assert expected[..., :3].std() > 10  # a drawn figure, not a blank one


def test_an_opaque_image_round_trips_as_rgb_and_a_translucent_one_keeps_its_alpha():
    rng = np.random.default_rng(1)
    rgba = rng.integers(0, 256, size=(7, 5, 4), dtype=np.uint8)
    rgba[..., 3] = 255
    with Image.open(io.BytesIO(encode_png(pixel_image(rgba), 120))) as im:
        assert im.mode == "RGB" and np.array_equal(np.asarray(im), rgba[..., :3])
    rgba[3, 2, 3] = 17
    with Image.open(io.BytesIO(encode_png(pixel_image(rgba), 120))) as im:
        assert im.mode == "RGBA" and np.array_equal(np.asarray(im), rgba)
