"""What a reader of a study should not miss, in words, from its summary rows: a scan that does
not fit its sensor model, points on a band edge, a stage that removes more than half of a cloud, a field without a
valid voxel. The report and ``lidarfield run`` print these statements."""

from __future__ import annotations

# A stage that removes more than this share of a cloud stands out: one hypothesis explaining
# half of a scan is more likely a wrong setting (a sensor model, a range) than a finding.
LARGE_REMOVAL = 0.5


def removed_share(row: dict, cloud: int) -> float:
    """The share of the cloud entering the stage that the stage removed (0 for an empty cloud)."""
    removed, kept = int(row.get(f"removed{cloud}") or 0), int(row.get(f"n{cloud}") or 0)
    return removed / (removed + kept) if removed + kept else 0.0


def stage_findings(row: dict) -> list[str]:
    """The statements about one stage (a summary row)."""
    found = []
    for cloud in (1, 2):
        share = removed_share(row, cloud)
        if share > LARGE_REMOVAL:
            entering = int(row[f"removed{cloud}"]) + int(row[f"n{cloud}"])
            found.append(
                f"{row.get('hypothesis')} removed {share:.0%} of cloud {cloud} ({int(row[f'removed{cloud}'])} of "
                f"{entering} points)"
            )
    if row.get("field_warning"):
        found.append(str(row["field_warning"]))
    return found


def sensor_findings(row: dict) -> list[str]:
    """A scan of the pair that does not fit its sensor model (the same in each of its rows)."""
    return [str(row["sensor_warning"])] if row.get("sensor_warning") else []


def grid_findings(row: dict) -> list[str]:
    """Points of the pair clustering on a band edge nobody could move (field.channels)."""
    return [str(row["binning_warning"])] if row.get("binning_warning") else []


def pair_findings(row: dict) -> list[str]:
    """The statements about the pair a summary row belongs to (the same in each of its rows)."""
    return sensor_findings(row) + grid_findings(row)


def findings_items(rows: list[dict]) -> list[str]:
    """Every statement of the rows, pair by pair in their order, stages by level."""
    items = []
    for pair in dict.fromkeys(str(r.get("pair")) for r in rows):
        pair_rows = sorted((r for r in rows if str(r.get("pair")) == pair), key=lambda r: float(r.get("level") or 0))
        items += [f"pair {pair}: {text}" for text in pair_findings(pair_rows[0])]
        items += [f"pair {pair}, stage {r.get('stage')}: {text}" for r in pair_rows for text in stage_findings(r)]
    return items
