"""The job layer: one TOML job run end to end, as a sequence of small steps (docs/architecture.md).

==================  ==============================================================================
module              step
==================  ==============================================================================
:mod:`.inputs`      read (or simulate) the job's data; the filter's IMU error model
:mod:`.windows`     the job's GNSS outage windows
:mod:`.initialization`  the filter's initial nominal state and sigmas
:mod:`.aiding`      measurement models (GNSS, ZUPT, ZARU, NHC, CUPT, odometer)
:mod:`.result`      what a run produced (:class:`~.result.JobResult`)
:mod:`.context`     a prepared run, as handed to a process
:mod:`.evaluation`  errors against the reference, outage metrics
:mod:`.summary`     ``summary.json``
:mod:`.processes`   the table of process models (strapdown, RISS, foot) running the engine
:mod:`.segments`    split runs: one run per contiguous IMU segment, merged
:mod:`.outputs`     trajectories, logs, summary, report as one file set
:mod:`.run`         preparation (IMU policies, windows, time offset) and the run itself
==================  ==============================================================================

A module imports only modules listed above it (``run`` passes its single-run function into
``segments``); :mod:`insgnss.pipeline` is the public facade that re-exports the names users
import.
"""
