"""End-to-end processing of a job (docs/jobs.md, docs/architecture.md): the public entry points
of the job layer, :mod:`insgnss.job`.

A job runs as a sequence of steps, each a small module of :mod:`insgnss.job`::

    load_inputs        job.inputs          read (or simulate) the data; the filter's IMU model
    outage_windows     job.windows         GNSS outage windows in the job's time base
    (preparation)      job.run.prepare     IMU table policies, estimated IMU time offset
    initialize         job.initialization  initial nominal state and sigmas
    build_measurements job.aiding          aiding measurement models
    filter_config      job.processes       engine settings; the process model table
                                           (strapdown, RISS, foot) runs the filter engine
    (split runs)       job.segments        one run per IMU segment, merged
    evaluate_solution  job.evaluation      errors against the reference, outage metrics
    incomplete_reason  job.summary         summary.json; why a run is incomplete;
    measurement_rows                       the measurement counts as text lines
    write_outputs      job.outputs         trajectories, logs, summary, report (one file set)
    run_job, process   job.run             all of the above in memory / and write the outputs

This module only re-exports those names, so that ``from insgnss.pipeline import run_job`` (the
CLI, batch and Monte Carlo runs, comparisons, benchmarks) keeps working; it holds no logic.
"""

from __future__ import annotations

from .job.aiding import build_measurements
from .job.evaluation import evaluate_solution
from .job.initialization import Initialization, initialize
from .job.inputs import Inputs, load_inputs
from .job.outputs import OUTPUT_NAMES, write_outputs
from .job.processes import filter_config
from .job.result import JobResult, PresetResult
from .job.run import process, run_job
from .job.summary import incomplete_reason, measurement_rows
from .job.windows import outage_windows

__all__ = ["OUTPUT_NAMES", "Inputs", "Initialization", "JobResult", "PresetResult",
           "build_measurements", "evaluate_solution", "filter_config", "incomplete_reason",
           "initialize", "load_inputs", "measurement_rows", "outage_windows", "process",
           "run_job", "write_outputs"]
