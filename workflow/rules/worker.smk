# A local run hands each job to a pre-imported worker (lidarfield.runner.server), started as the
# run's planning starts and stopped when the run ends (or at exit, when it has nothing to do):
# jobs then skip Python's start and imports. With LIDARFIELD_WORKER=off every job is its own
# process. On a SLURM cluster (profiles/slurm) each allocation's Snakemake starts one of its own.
# The scheduler keeps one pending re-evaluation timer, not one chain of them per job done, and
# the end of a run cancels it (see lidarfield.runner.scheduling): it would otherwise hold the
# exit for up to a minute.
import gc

from lidarfield.runner import launch, scheduling

scheduling.coalesce_reevaluations()

# Not in the Snakemake processes that run one job each (on a cluster node), nor when each job
# runs in its rule's own software environment (--sdm conda / apptainer): the worker runs the
# jobs with its own imports, those of the environment Snakemake runs in.
NO_DEPLOYMENT = not workflow.deployment_settings.deployment_method
USE_WORKER = workflow.is_main_process and NO_DEPLOYMENT
# Started importing as Snakemake starts planning a run that executes jobs here, so the run's
# first jobs need not wait for it; a dry run, --lint, --dag or --summary starts nothing. It
# warms up for the figures when the study draws enough of them.
if USE_WORKER:
    launch.spawn_when_planning(
        workflow, RESULTS, figure_jobs=sum(len(STAGES[pair]) for pair in PLOT_PAIRS)
    )
# The one Snakemake of a SLURM allocation (profiles/slurm) runs a batch of jobs: its worker
# starts now, as hooks do not run there. The batch's jobs are its command line's
# --target-jobs (RULE:WILDCARDS), which Snakemake has not parsed yet.
elif NO_DEPLOYMENT and launch.in_allocation(workflow.remote_exec):
    launch.start_in_allocation(
        RESULTS, figure_jobs=sum(arg.startswith("plot_stage:") for arg in sys.argv)
    )


onstart:
    gc.freeze()  # the plan, out of the collections of the run (see common.smk)
    gc.enable()
    if USE_WORKER and launch.executes_here(workflow):
        launch.start(RESULTS)
    else:
        launch.stop()  # jobs run on cluster nodes, in their own environments, or not (--touch)


onsuccess:
    launch.stop()
    scheduling.cancel_pending_rounds()


onerror:
    launch.stop()
    scheduling.cancel_pending_rounds()
