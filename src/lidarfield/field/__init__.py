"""The discrepancy-vector field: voxel grids, the fast kernel and its plain reference, the
per-voxel standard errors, and the field file."""
