"""A study: its config (validated against the schema), its pairs and scans, the hypothesis
stack and its stage ids, the workflow's jobs, the summary, and one pair run without Snakemake."""
