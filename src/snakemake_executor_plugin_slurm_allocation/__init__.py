"""Snakemake's SLURM executor, with one Snakemake per allocation running its jobs in parallel:
``--executor slurm-allocation`` (profiles/slurm).

snakemake-executor-plugin-slurm submits each job group as one allocation whose Snakemake runs
the group's jobs through its jobstep executor, one at a time (``--jobs 1``) and each as its own
``srun`` and Snakemake: a group of n jobs costs 1 + n Snakemake starts on one core. This plugin
changes only what the allocation runs: its one Snakemake executes the group's jobs with
Snakemake's local executor, shell commands in threads, as many at once as the allocation has
cores. Submission, status queries, cancelling and the settings are the SLURM plugin's (its
options are spelled ``--slurm-allocation-...`` here).

One more change: when it polls. The SLURM plugin polls on its own clock, 10 s later after
every poll that saw no allocation end (up to 180 s): an allocation is seen ended up to minutes
late, and a drive pays that at each of its rounds (scans, pairs, study). Here the next poll
also comes within ``POLL_FRACTION`` of the time since the last change (a submission, or an
allocation seen ended), but never sooner than ``init-seconds-before-status-checks`` after
the last: an allocation that started when another ended is seen ended about a tenth of its
run time late.
"""

from __future__ import annotations

import asyncio
import time

from snakemake_interface_common.exceptions import WorkflowError
from snakemake_interface_executor_plugins.jobs import JobExecutorInterface

try:
    import snakemake_executor_plugin_slurm as slurm
except ImportError:  # the lidarfield[slurm] extra is not installed
    slurm = None

# lidarfield.runner.launch.ALLOCATION_ENV: read by the workflow inside the allocation.
ALLOCATION_ENV = "LIDARFIELD_SLURM_ALLOCATION"
# The next poll comes at most this fraction of the time since the last change later.
POLL_FRACTION = 0.1

if slurm is None:
    from snakemake_interface_executor_plugins.executors.remote import RemoteExecutor
    from snakemake_interface_executor_plugins.settings import CommonSettings

    common_settings = CommonSettings(non_local_exec=True, implies_no_shared_fs=False, job_deploy_sources=False)

    class Executor(RemoteExecutor):  # registered, but refuses to run: Snakemake loads every plugin it finds
        def __post_init__(self):
            raise WorkflowError(
                "the slurm-allocation executor needs snakemake-executor-plugin-slurm: pip install 'lidarfield[slurm]'"
            )

else:
    common_settings = slurm.common_settings
    ExecutorSettings = slurm.ExecutorSettings

    class Executor(slurm.Executor):
        # The SLURM jobs running at the last poll and when they last changed; class attributes,
        # as polling starts in a thread before __post_init__ runs.
        polled_jobs: frozenset[str] = frozenset()
        last_change = 0.0

        def __post_init__(self, test_mode: bool = False):
            super().__post_init__(test_mode)
            if self.workflow.executor_settings.array_jobs:
                raise WorkflowError(
                    "--slurm-allocation-array-jobs: array jobs run each task through the jobstep "
                    "executor; use job groups (profiles/slurm) instead"
                )

        async def sleep(self) -> None:
            running = frozenset(info.external_jobid for info in list(self.active_jobs))
            now = time.monotonic()
            if running != self.polled_jobs:  # a submission, or an allocation seen ended
                self.polled_jobs, self.last_change = running, now
            await asyncio.sleep(
                next_poll_s(
                    self.next_seconds_between_status_checks,
                    now - self.last_change,
                    self.workflow.executor_settings.init_seconds_before_status_checks,
                )
            )

        def get_job_exec_prefix(self, job: JobExecutorInterface) -> str:
            return f"export {ALLOCATION_ENV}=1"

        def get_job_args(self, job: JobExecutorInterface) -> str:
            # The last --cores wins: the allocation's Snakemake runs as many jobs at once as
            # the CPUs the submission asks for (the plugin's --cores is the profile's cap).
            return f"{super().get_job_args(job)} --cores {allocation_cpus(job)}"

        def additional_general_args(self) -> str:
            return "--executor local --keep-going --show-failed-logs"


def allocation_cpus(job: JobExecutorInterface) -> int:
    """The CPUs the submission of ``job`` asks for (``--cpus-per-task``, as the SLURM plugin
    sets it): its ``cpus_per_task`` resource, else its threads (a group's: the most of its jobs
    that run at once, capped by ``--cores``)."""
    cpus = job.resources.get("cpus_per_task") or job.threads
    return max(1, int(cpus))


def next_poll_s(plugin_interval_s: float, unchanged_s: float, shortest_s: float) -> float:
    """Seconds to the next poll: the SLURM plugin's interval, or sooner, ``POLL_FRACTION`` of
    the time the running allocations have been ``unchanged_s``, but no less than ``shortest_s``
    (``init-seconds-before-status-checks``)."""
    return min(plugin_interval_s, max(shortest_s, POLL_FRACTION * unchanged_s))
