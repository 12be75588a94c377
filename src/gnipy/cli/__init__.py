"""The `gni` command line: run a model with any method and write netCDF; convergence studies;
parameter sweeps; summaries and checks of result files; the paper's reproduction; the demo;
listings.

    gni run MODEL --method METHOD --h H (--steps N | --t-final T) [--set NAME=VALUE ...]
            [--q0 a,b,...] [--v0 a,b,...] [--R0 r11,...,r33] [--project-v0] [--save-every K]
            [--plot FILE.png] [--config RUN.toml] [--out FILE.nc]
    gni convergence MODEL --methods M1,M2 --h-max A --h-min B --count N [--t-final T]
            [--set NAME=VALUE ...] [--q0 ...] [--v0 ...] [--R0 ...] [--error state|q|v] --out DIR
    gni stability MODEL --over NAME=START:STOP:COUNT [--set NAME=VALUE ...] [--q0 ...] [--v0 ...]
            [--methods M1,M2 --h H] --out DIR
    gni sweep MODEL --grid "NAME=linspace(START, STOP, COUNT)" ... --h H (--steps N | --t-final T) --out DIR.zarr
    gni control (PROBLEM.toml | --example NAME) [--print] --out FILE.nc [--plot FILE.png]
    gni fit PROBLEM.toml --out FILE.nc [--plot FILE.png]
    gni info (FILE.nc | DIR.zarr | FILE.nc.parts)
    gni verify PATH
    gni reproduce [--out DIR] [--quick]
    gni atlas [--quick] [--out DIR] [--models a,b] [--methods x,y]
    gni open-questions [--quick] [--out DIR]
    gni demo [--out FILE.nc]
    gni models
    gni methods

Bad input gives a one-line message naming the option and exit code 2; a solver failure or a file
that cannot be written gives exit code 1. Neither prints a Python traceback.

**Files** (:mod:`gnipy.files`). An existing output file is replaced only with `--overwrite`; a
symbolic link, a directory, a FIFO or a device is never written to. Every file is written
atomically (a temporary file beside it, renamed when complete): a full disk or an interrupt leaves
an existing file as it was and no temporary behind. An output directory that gnipy creates
(`gni convergence --out DIR`, `gni stability --out DIR`, `gni reproduce --out DIR`) gets the marker `.gnipy-owned`; in such a
directory gnipy replaces its own files on a rerun, in any other directory only with `--overwrite`.
`--overwrite` and `--yes` are command-line options only: a configuration file cannot grant them.

**Terminal output.** Text from files and from the command line (paths, attributes, names) is
printed literally (no rich markup), with control characters shown as escapes (`\\x1b`). Long
commands show their progress as a bar on a terminal and as plain lines elsewhere
(:mod:`gnipy.cli.progress`).

The package holds parsing and printing only; what the commands compute lives in the library
(:func:`gnipy.simulate`, :func:`gnipy.analysis.convergence_study`, :func:`gnipy.analysis.stability_curve`, :func:`gnipy.sweep.run_sweep`,
:mod:`gnipy.experiments`). Its modules:

- :mod:`~gnipy.cli.app`: the typer app and `--version`;
- :mod:`~gnipy.cli.output`, :mod:`~gnipy.cli.errors`, :mod:`~gnipy.cli.progress`: printing,
  one-line errors naming options, progress;
- :mod:`~gnipy.cli.parsing`, :mod:`~gnipy.cli.config`, :mod:`~gnipy.cli.paths`,
  :mod:`~gnipy.cli.resources`: options, configuration files, output paths, bounds;
- one module per command group: :mod:`~gnipy.cli.run` (`run`, with
  :mod:`~gnipy.cli.summary`), :mod:`~gnipy.cli.demo`, :mod:`~gnipy.cli.convergence`, :mod:`~gnipy.cli.stability`, :mod:`~gnipy.cli.sweep`,
  :mod:`~gnipy.cli.control`, :mod:`~gnipy.cli.fit`, :mod:`~gnipy.cli.info` (`info`, `verify`), :mod:`~gnipy.cli.reproduce`,
  :mod:`~gnipy.cli.atlas`, :mod:`~gnipy.cli.open_questions`, :mod:`~gnipy.cli.listings` (`models`, `methods`).
"""

from .app import app, main

# the commands register on `app` when their modules are imported, in the order `gni --help` lists them
from . import run, convergence, stability, sweep, control, fit, info, demo, listings, reproduce, atlas, open_questions  # noqa: E402, F401  isort: skip

__all__ = ["app", "main"]
