# A local run hands each job to a pre-imported worker (lidarfield.worker), started here and
# stopped when the run ends: jobs then skip Python's start and imports. On a cluster, or with
# LIDARFIELD_WORKER=off, every job is its own process.
# The end of a run also cancels the scheduler's pending re-evaluation timers (see
# lidarfield.scheduling), which would otherwise hold the exit for up to a minute.
import lidarfield.scheduling
import lidarfield.worker


onstart:
    if workflow.local_exec:
        lidarfield.worker.start(RESULTS)


onsuccess:
    lidarfield.worker.stop()
    lidarfield.scheduling.cancel_pending_rounds()


onerror:
    lidarfield.worker.stop()
    lidarfield.scheduling.cancel_pending_rounds()
