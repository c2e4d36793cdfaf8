"""The analysis of fields and studies: what a field's vectors and their pattern say, and what
to try next.

- ``significance``: each vector's standard error and z score;
- ``randomness``: is what is left of a field random (direction and coherence tests, verdict);
- ``tags``: where each discrepancy could come from (geometric tags, energy shares);
- ``field_stats``: a field's summary statistics (sizes, rigid part, the above together);
- ``suggest``: every candidate hypothesis on its own, ranked (``suggestions.parquet``);
- ``rematch``: does a stage's mitigation make scan matching better;
- ``study``: the study level's tables over all pairs;
- ``findings``: what a reader of a study should not miss, in words.

Nothing is imported here: each job imports only the modules it uses.
"""
