"""The check of a figure's fixed layout: every panel, legend and title inside the figure, none
overlapping another (the figures use fixed margins, no layout engine)."""

from __future__ import annotations


def assert_fixed_layout(fig) -> None:
    renderer = fig.canvas.get_renderer()
    # a twin axes (same position as another) is one panel with it; a colour bar is a panel too
    panels = {ax.get_position().bounds: ax for ax in fig.axes if ax.get_visible()}
    boxes = [(f"axes {i}", ax.get_tightbbox(renderer)) for i, ax in enumerate(panels.values())]
    boxes += [("legend", leg.get_window_extent(renderer)) for leg in fig.legends]
    if fig._suptitle is not None:
        boxes.append(("suptitle", fig._suptitle.get_window_extent(renderer)))
    frame = fig.bbox
    name = fig.axes[0].get_title() or (fig._suptitle.get_text() if fig._suptitle else "?")
    for label, box in boxes:
        assert (
            box.x0 >= frame.x0 - 1 and box.x1 <= frame.x1 + 1 and box.y0 >= frame.y0 - 1 and box.y1 <= frame.y1 + 1
        ), f"{name!r}: {label} leaves the figure"
    for i, (la, a) in enumerate(boxes):
        for lb, b in boxes[i + 1 :]:
            overlap_x = min(a.x1, b.x1) - max(a.x0, b.x0)
            overlap_y = min(a.y1, b.y1) - max(a.y0, b.y0)
            assert overlap_x <= 2 or overlap_y <= 2, f"{name!r}: {la} overlaps {lb}"
