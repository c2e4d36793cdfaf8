# A local run hands each job to a pre-imported worker (lidarfield.worker), started here and
# stopped when the run ends: jobs then skip Python's start and imports. On a cluster, or with
# LIDARFIELD_WORKER=off, every job is its own process.
import lidarfield.worker


onstart:
    if workflow.local_exec:
        lidarfield.worker.start(RESULTS)


onsuccess:
    lidarfield.worker.stop()


onerror:
    lidarfield.worker.stop()
