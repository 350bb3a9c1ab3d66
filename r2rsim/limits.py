"""Size limits on what an input file may ask of r2rsim, and why each has the value it has.

Every limit is checked when a file is loaded (or when ``--duration``/``--seed`` override it),
before anything is compiled or simulated, and a file over a limit is refused with one
``file: yaml.path: problem`` line naming the limit. ``docs/security.md`` lists them for users.
The values sit one to three orders of magnitude above anything a real line or scenario needs
(the shipped files are all below 7.5 kB and at most 600 s at up to 500 Hz), so that they only
stop files that would otherwise exhaust memory or run for hours before failing.
"""

from __future__ import annotations

import math

#: Largest line or scenario file read [bytes]: 1 MiB. The largest shipped file is 7.4 kB and a
#: generated 1000-element line about 150 kB; parsing and validating 1 MiB of YAML takes about a
#: second, and the limit keeps a path such as /dev/zero (endless) or a huge file from filling
#: memory before the YAML parser sees it.
MAX_FILE_BYTES = 1 << 20

#: Deepest nesting of YAML lists and mappings. Line and scenario files nest at most 6 levels
#: (``elements[0].pressure_roller.friction.viscous``); the YAML parser and the validation
#: recurse once per level, so thousands of levels would exhaust the stack (a crash in libyaml).
MAX_NESTING = 32

#: Most values (scalars, lists, mappings) a file may expand to, YAML aliases included. A 1 MiB
#: file holds at most ~500 000 values written out ("1,1,1,..."), so only aliases can exceed
#: it: aliases of aliases make a 1 kB file expand to billions ("billion laughs"), which
#: validation would then walk. Real files have a few hundred to a few thousand values.
MAX_VALUES = 500_000

#: Most characters in a YAML integer. ``seed`` needs at most 20 digits (2**64 - 1); Python
#: refuses to read integers of more than 4300 digits with a ValueError, not a YAML error.
MAX_INT_CHARS = 100

#: Largest simulated duration [s]: 1e6 s (11.6 days). The slowest reference line (Line C,
#: physics.md §2.3) empties a full roll in 9.3 h; a run of several roll changes of it fits.
MAX_DURATION_S = 1.0e6

#: Highest record rate [Hz]: 100 kHz. The fastest dynamics r2rsim models are the drives'
#: current loops (0.2-2 ms, physics.md §2.2) and real load cells and encoders sample at
#: <= 10 kHz; 100 kHz resolves the fastest torque lag with margin. Higher rates only multiply
#: the data (1 MHz ran out of Arrow memory).
MAX_RECORD_RATE_HZ = 1.0e5

#: Most samples in one run (duration x record rate): 1e8. That is 28 h at 1 kHz; at ~50
#: float32 columns it is ~20 GB before compression and hours of wall time. The samples are
#: streamed, so the limit is about disk and time, not memory; 1e300 samples failed with
#: "Maximum allowed size exceeded" only after the line had been compiled.
MAX_SAMPLES = 1.0e8

#: Most programme steps: 10 000. Every step is a solver breakpoint (a restart, ~1 ms of wall
#: time each); 10 000 is a set-point change every 10 ms for 100 s. A 1.3-million-step programme
#: ran for 262 s and 3.7 GB before failing with a SystemError in the programme tables.
MAX_PROGRAMME_STEPS = 10_000

#: Most scheduled events (splices, e-stops, dancer seizures): 1000; each is a discrete change
#: with a solver restart; a real scenario has a handful.
MAX_EVENTS = 1_000

#: Most faults in one scenario: 1000. Each fault is checked against every other one on its
#: target for overlaps (quadratic) and becomes a row of faults.parquet; real scenarios have
#: one to ten.
MAX_FAULTS = 1_000

#: Most process disturbances: 1000 (one per roller and kind is already generous).
MAX_DISTURBANCES = 1_000

#: Most elements, sensors or controllers in a line: 10 000. The largest benchmark line has 500
#: spans (benchmarks/bench_solver.py); the compiled kernel grows with the line.
MAX_LINE_ITEMS = 10_000

#: Largest root seed: 2**64 - 1. numpy's SeedSequence takes any non-negative integer, but the
#: seed is stored as uint64 in runs.parquet (a larger one failed after the whole simulation).
MAX_SEED = (1 << 64) - 1


def run_size_problem(duration: float, record_rate: float) -> tuple[str, str] | None:
    """``(key, why)`` when a run's duration [s] and record rate [Hz] exceed the limits above
    (``key`` is ``duration`` or ``record_rate``), else None. Non-positive or non-finite values
    are reported too, so that API callers get the same answer as the schema's."""
    if not (math.isfinite(duration) and duration > 0):
        return "duration", f"must be a finite time > 0, got {duration!r}"
    if not (math.isfinite(record_rate) and record_rate > 0):
        return "record_rate", f"must be a finite rate > 0, got {record_rate!r}"
    if duration > MAX_DURATION_S:
        return "duration", (
            f"{duration:.10g} s is longer than the limit of {MAX_DURATION_S:g} s "
            f"({MAX_DURATION_S / 86400:.1f} days; docs/security.md)"
        )
    if record_rate > MAX_RECORD_RATE_HZ:
        return "record_rate", (
            f"{record_rate:.10g} Hz is above the limit of "
            f"{MAX_RECORD_RATE_HZ:g} Hz (docs/security.md): nothing in the "
            "model is faster than the drives' ~1 ms torque lag"
        )
    samples = duration * record_rate
    if samples > MAX_SAMPLES:
        return "duration", (
            f"{duration:g} s at {record_rate:g} Hz is {samples:.3g} samples, "
            f"more than the limit of {MAX_SAMPLES:.0e} per run "
            "(docs/security.md); lower the record rate or split the run"
        )
    return None


def wound_in_strain_points(v_max: float, duration: float, correlation_length: float) -> float:
    """Size of a wound-in-strain disturbance's table (``shape: table``): ten points per
    correlation length over 1.5 times the web that can pass in the run
    (:mod:`r2rsim.compile.disturbances`). It is held in memory, so it is bounded like the
    samples (:data:`MAX_SAMPLES`)."""
    dx = correlation_length / 10.0
    return (1.5 * v_max * duration + 10.0 * correlation_length) / dx + 2


#: Most runs in one sweep: 100 000 (combinations x seeds). The Tennessee Eastman sets have
#: 500 runs per fault; 100 000 short runs is days of CPU on one machine, and every run is a
#: row of runs.parquet and a directory of samples/. Checked before anything is validated.
MAX_SWEEP_RUNS = 100_000

#: Most values of one sweep axis (a list or a range): 10 000.
MAX_AXIS_VALUES = 10_000

#: Most worker processes a sweep starts on this machine (--workers, also a LocalCluster's):
#: 1024. Each loads numba's kernels (~300 MB); the largest single machines have a few
#: hundred cores. A sweep never starts more workers than it has runs to do.
MAX_LOCAL_WORKERS = 1024

#: Most bootstrap replicates of an evaluation: 100 000. The replicate index is held in
#: memory (replicates x runs), and 10 000 already puts a 95 % interval's ends within a few
#: tenths of a percent of their limit.
MAX_BOOTSTRAP = 100_000

#: Longest VUS-PR buffer (``vus_buffer``) [s]: 60 s. The buffer is a tolerance on when an alarm
#: comes (one this long before a logged onset or after a fault's end still counts); a few
#: seconds is typical for the thesis lines (docs/diagnostics.md §5.4), and a minute is longer
#: than any loop of physics.md takes to settle. Checked before any dataset is read or simulated.
MAX_VUS_BUFFER_S = 60.0

#: Most VUS-PR buffer lengths [samples]: 10 000 (60 s at 166 Hz). ``metrics.vus_pr`` computes
#: one range-based PR-AUC over every pooled sample of a stratum per buffer length, about 0.1 µs
#: per sample each: 10 000 lengths over 10^5 samples take about 1.5 min per stratum. A
#: ``--vus-buffer 1e9`` (10^11 lengths) ran for hours. Checked once the test runs' sample
#: period is known, before the plug-in is fitted, and by ``vus_pr`` itself.
MAX_VUS_BUFFER_SAMPLES = 10_000
