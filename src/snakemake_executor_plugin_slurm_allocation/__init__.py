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
every poll that saw no allocation end (up to 180 s): a 10-s allocation submitted after a few
such polls is seen ended a minute late, and a drive pays that at each of its rounds (scans,
pairs, study). Here the next poll also comes within ``POLL_FRACTION`` of the age of the oldest
running allocation (never sooner than ``init-seconds-before-status-checks``): an allocation
is seen ended at most about a fifth of its age late.

The allocation's command also names the allocation in ``LIDARFIELD_SLURM_ALLOCATION``, so
that the workflow starts its job worker there (workflow/rules/worker.smk), and keeps going
after a failed job, so that the other pairs of a batch finish, and prints the failed job's log
into the allocation's SLURM log.

Snakemake finds executor plugins by the name of their top-level module
(``snakemake_executor_plugin_<name>``); this one comes with the lidarfield distribution and
imports nothing of lidarfield: every Snakemake start imports every installed plugin.
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
# The next poll comes at most this fraction of the oldest running allocation's age later.
POLL_FRACTION = 0.2

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
        def __post_init__(self, test_mode: bool = False):
            super().__post_init__(test_mode)
            if self.workflow.executor_settings.array_jobs:
                raise WorkflowError(
                    "--slurm-allocation-array-jobs: array jobs run each task through the jobstep "
                    "executor; use job groups (profiles/slurm) instead"
                )
            self.submitted_at: dict[str, float] = {}  # SLURM job id -> time.monotonic()

        def report_job_submission(self, job_info, register_job: bool = True) -> None:
            if job_info.external_jobid is not None:
                self.submitted_at[job_info.external_jobid] = time.monotonic()
            super().report_job_submission(job_info, register_job)

        async def sleep(self) -> None:
            ages = [
                time.monotonic() - self.submitted_at[info.external_jobid]
                for info in list(self.active_jobs)
                if info.external_jobid in self.submitted_at
            ]
            await asyncio.sleep(
                next_poll_s(
                    self.next_seconds_between_status_checks,
                    ages,
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


def next_poll_s(plugin_interval_s: float, ages_s: list[float], shortest_s: float) -> float:
    """Seconds to the next poll: the SLURM plugin's interval, or sooner, ``POLL_FRACTION`` of
    the oldest running allocation's age (``ages_s``: those of the allocations not yet seen
    ended) but no less than ``shortest_s`` (``init-seconds-before-status-checks``)."""
    if not ages_s:
        return plugin_interval_s
    return min(plugin_interval_s, max(shortest_s, POLL_FRACTION * max(ages_s)))
