"""The study's storage: the results folder's names (``layout``), the content-addressed stage
ids that name the stage folders (``stage_ids``), and how a stage's points are stored as what
it changed (``stage_points``)."""
