"""Running the workflow's jobs: the pre-imported job worker, its start and stop, the client
every job calls first, and the scheduler's timers."""
