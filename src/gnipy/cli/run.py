"""`gni run`: integrate a model with a method and write netCDF (and a figure).

Long runs are streamed (`--checkpoint-every K`, or more than
:data:`~gnipy.cli.resources.STREAM_NODES` saved nodes): the nodes go to the file in chunks through
:func:`gnipy.streaming.simulate_to_file`, and an interrupted run resumes (`--resume`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import typer

from . import resources
from .app import app
from .config import config_keys, load_config
from .errors import UsageError, WriteFailure, guarded, writing
from .output import exit_for_health
from .parsing import parse_R0, prepare
from .held import hold
from .paths import check_output, check_plot, same_file
from .progress import Progress, busy
from .summary import attrs_for, origin_attrs, run_report, streamed_report

__all__ = ["PROGRESS_STEPS", "CONFIG_KEYS", "run", "run_streamed", "simulate_model", "write_plot"]

#: In-memory runs of at least this many steps report their progress (a bar on a terminal, plain
#: lines elsewhere: :mod:`gnipy.cli.progress`); shorter ones show a spinner on a terminal only.
PROGRESS_STEPS = 10_000


@app.command()
def run(
    model: str | None = typer.Argument(
        None, help="Model name (see `gni models`), or your own system: FILE.py:NAME or module:NAME, "
        "NAME a function returning a gnipy.System (its number-valued keyword parameters are what --set "
        "reaches); or `model` in --config.",
        show_default=False, metavar="MODEL"
    ),
    method: str | None = typer.Option(
        None, "--method", "-m", help="Method name (see `gni methods`). [default: the model's, see `gni models`]", show_default=False
    ),
    h: float | None = typer.Option(None, "--h", help="Step size (> 0).", show_default=False),
    steps: int | None = typer.Option(
        None, "--steps", help="Number of steps (give this or --t-final).", show_default=False
    ),
    t_final: float | None = typer.Option(
        None, "--t-final", help="Final time, a whole number of steps (give this or --steps).", show_default=False
    ),
    set_: list[str] | None = typer.Option(
        None, "--set", help="Parameter override NAME=VALUE (repeatable, or comma-separated).", show_default=False
    ),
    q0: str | None = typer.Option(
        None, "--q0", "--x0", help="Initial configuration a,b,... (default: the model's; --x0 is its older name).",
        show_default=False
    ),
    v0: str | None = typer.Option(
        None, "--v0", help="Initial velocity a,b,... (default: the model's).", show_default=False
    ),
    R0: str | None = typer.Option(
        None, "--R0", help="Initial orientation on R^n x G, row-major r11,...,r33 (default: the model's, or identity).",
        show_default=False,
    ),
    project_v0: bool | None = typer.Option(
        None, "--project-v0/--no-project-v0",
        help="Project v0 onto the constraints instead of rejecting it. [default: no]", show_default=False,
    ),
    save_every: int | None = typer.Option(
        None, "--save-every", help="Save every K-th node (and always the last). [default: 1]", show_default=False
    ),
    out: Path | None = typer.Option(
        None, "--out", "-o", help="Output netCDF file. Without it the run prints its summary and writes nothing "
        "(a streamed run needs it).", show_default=False,
    ),
    plot: Path | None = typer.Option(
        None, "--plot", help="Also write a figure (configuration path, energy error, constraint residual and, "
        "for the GNI family, the hidden momentum), e.g. run.png.", show_default=False,
    ),
    config: Path | None = typer.Option(
        None, "--config", "-c", help="A TOML file with any of these options (keys as the option names, "
        "dashes or underscores); options given on the command line override it.", show_default=False,
    ),
    checkpoint_every: int | None = typer.Option(
        None, "--checkpoint-every", help="Stream the run in chunks of K steps (a multiple of --save-every), "
        "each committed to OUT.parts/ with the integrator state, so that an interrupted run can be resumed "
        "(--resume). Runs saving more than 10^6 nodes are streamed in any case.", show_default=False,
    ),
    resume: bool = typer.Option(
        False, "--resume", help="Continue an interrupted streamed run of the same options from its last "
        "checkpoint (the result equals an uninterrupted run exactly).",
    ),
    overwrite: bool = typer.Option(
        False, "--overwrite", help="Replace existing --out and --plot files (without it they are refused; a "
        "symbolic link, directory or special file is refused always). Not read from --config.",
    ),
    yes: bool = typer.Option(
        False, "--yes", help="Run even when the memory or the file the run needs is estimated beyond gnipy's "
        "bounds (memory: the smaller of 8 GiB and half the RAM; file: 64 GiB, and the free disk space), which "
        "are otherwise refused before anything is compiled. Not read from --config.",
    ),
    accept_out_of_band: bool = typer.Option(
        False, "--accept-out-of-band", help="Exit 0 even when the run went qualitatively wrong (a verdict out "
        "of band at some step: the hidden momentum, a conserved energy), which otherwise exits with code 3 "
        "after writing the files. Not read from --config.",
    ),
):
    """Integrate MODEL with METHOD, print a summary and write the trajectory to a netCDF file (--out).

    Without --out the run prints its summary (health, errors, drifts) and writes nothing. The
    file holds t(time), q(time, coordinate), v(time, velocity), p(time, velocity), energy(time)
    and constraint_residual(time, constraint), and R(time, i, j) on R^n x G, with provenance
    attributes. With --plot, also a figure of the run.

    A config file holds the same options, e.g.

    \b
        model = "vertical-disk"
        method = "gni-midpoint"
        h = 0.05
        t-final = 10
        q0 = [0, 0, 0, 0]
        set = { I_rot = 2 }
        out = "disk.nc"

    (`set` may also be a list of "NAME=VALUE" strings, `q0`/`v0`/`R0` strings "a,b,..."; `x0` is
    read as `q0`).
    Relative paths in the file are relative to the file's directory.

    Long runs are streamed: with --checkpoint-every K (or when more than 10^6 nodes are saved)
    the nodes go to the file in chunks, memory holds one chunk, and the file appears (atomically)
    when the run is complete; --resume continues an interrupted run.
    """
    origins: dict[str, str] = {}  # option -> where its value came from (--config), for the messages

    def go():
        inputs = _run_inputs(config, origins, model=model, method=method, h=h, steps=steps, t_final=t_final,
                             set_=set_, q0=q0, v0=v0, R0=R0, project_v0=project_v0, save_every=save_every, out=out,
                             plot=plot, checkpoint_every=checkpoint_every)
        return _run(inputs, config, resume=resume, overwrite=overwrite, yes=yes)

    exit_for_health(guarded(go, origins), accept_out_of_band)


#: The keys of `gni run --config RUN.toml`: `gni run`'s own options (:func:`gnipy.cli.config.config_keys`),
#: less those that name the file, act on earlier output or grant what a file must not (replace
#: files, go past the resource bounds, exit 0 on a failed verdict).
CONFIG_KEYS = config_keys(run, command_line_only={"config", "resume", "overwrite", "yes", "accept_out_of_band"},
                          vectors={"q0", "v0", "R0"})


@dataclass
class _RunInputs:
    """The options of a `gni run`: each from the command line, else from --config, else its
    default (the method: the model's; the length, --steps or --t-final: both from one place)."""

    model: str
    method: str
    h: float
    steps: int | None
    t_final: float | None
    set_items: list[str]  # NAME=VALUE, the config file's first (the command line wins per name)
    q0: str | None
    v0: str | None
    R0: str | None
    project_v0: bool
    save_every: int
    out: Path | None  # None: the summary only, nothing written
    plot: Path | None
    checkpoint_every: int | None


def _run_inputs(config: Path | None, origins: dict[str, str], *, model, method, h, steps, t_final, set_, q0, v0, R0,
                project_v0, save_every, out, plot, checkpoint_every) -> _RunInputs:
    """The options of `gni run` from those of the command line (the keyword arguments, None where
    not given) and the file `config`; `origins` records the options read
    from the file (option -> `"key 'h' in FILE"`). Raises UsageError for a missing model or --h."""
    cfg: dict[str, Any] = {}
    if config is not None:
        cfg = load_config(config, CONFIG_KEYS)
        for key in cfg:
            origins[CONFIG_KEYS[key][0]] = f"key {key.replace('_', '-')!r} in {str(config)}"

    def pick(key: str, given, default=None):
        if given is not None:
            origins.pop(CONFIG_KEYS[key][0], None)
            return given
        return cfg.get(key, default)

    model_ = pick("model", model)
    if model_ is None:
        raise UsageError("MODEL", "missing: give MODEL (or `model` in --config)")
    method_ = pick("method", method)
    if method_ is None:  # the model's measured default (gni models shows it and why)
        from gnipy.registry import default_method_for

        method_ = default_method_for(str(model_))
    h_ = pick("h", h)
    if h_ is None:
        raise UsageError("--h", "missing: give --h (or `h` in --config)")
    if steps is not None or t_final is not None:  # the command line decides the length
        steps_, t_final_ = steps, t_final
        origins.pop("--steps", None)
        origins.pop("--t-final", None)
    else:
        steps_, t_final_ = cfg.get("steps"), cfg.get("t_final")
    set_items = list(cfg.get("set", [])) + list(set_ or [])  # the command line wins per name
    if set_:
        origins.pop("--set", None)
    inputs = _RunInputs(
        model=model_, method=method_, h=h_, steps=steps_, t_final=t_final_, set_items=set_items,
        q0=pick("x0" if "x0" in cfg else "q0", q0), v0=pick("v0", v0), R0=pick("R0", R0),
        project_v0=bool(pick("project_v0", project_v0, False)),
        save_every=pick("save_every", save_every, 1), out=pick("out", out), plot=pick("plot", plot),
        checkpoint_every=pick("checkpoint_every", checkpoint_every),
    )
    return inputs


def _run(inputs: _RunInputs, config: Path | None, *, resume: bool, overwrite: bool, yes: bool) -> bool:
    """`gni run` with its options read: checks them and the outputs, runs in memory or streamed,
    writes and reports; returns whether the run is healthy (or failed)."""
    spec, params, q0, v0 = prepare(inputs.model, inputs.method, inputs.h, inputs.steps, inputs.t_final,
                                   inputs.set_items, inputs.q0, inputs.v0, inputs.save_every)
    R0 = parse_R0(spec, params, inputs.R0)
    _check_outputs(inputs.out, inputs.plot, overwrite, resume)
    chunk = inputs.checkpoint_every
    if inputs.out is None and (chunk is not None or resume):
        option = "--checkpoint-every" if chunk is not None else "--resume"
        raise UsageError("--out", f"missing: {option} streams the run into a file; give --out FILE.nc")
    if chunk is not None and (isinstance(chunk, bool) or chunk < 1):
        raise UsageError("--checkpoint-every", f"must be a positive integer, got {chunk!r}")
    if resume and chunk is None:
        raise UsageError("--resume", "only streamed runs resume: give --checkpoint-every K as in the interrupted run")
    from gnipy.simulate import MAX_STEPS, resolve_steps

    n_steps = resolve_steps(inputs.h, inputs.steps, inputs.t_final)[1]
    stride = min(int(inputs.save_every), n_steps)  # the stride the run has (the last node is always saved)
    streamed = chunk is not None or n_steps // stride > resources.STREAM_NODES or n_steps > MAX_STEPS
    if streamed:
        if inputs.out is None:
            why = (f"saves more than {resources.STREAM_NODES:,} nodes" if n_steps // stride > resources.STREAM_NODES
                   else f"takes more than {MAX_STEPS:,} steps")
            raise UsageError("--out", f"missing: the run {why} and is streamed into a file; give --out FILE.nc")
        chunk = _streamed_chunk(inputs, stride, chunk)
    length = "--steps" if inputs.steps is not None else "--t-final"
    if not yes:  # estimated before anything is compiled or allocated
        resources.check_resources(spec.build(params), n_steps, stride, streamed, chunk, inputs.out, length,
                                  chunk_given=inputs.checkpoint_every is not None)
    if streamed:
        extra = _run_attrs(stride, inputs.project_v0, config, R0, q0=list(q0),
                           coordinates=",".join(spec.coordinates))
        return run_streamed(spec, params, inputs.method, q0, v0, R0, inputs.h, inputs.steps, inputs.t_final,
                            inputs.project_v0, stride, chunk, resume, inputs.out, extra, overwrite=overwrite, yes=yes)
    return _run_in_memory(spec, params, inputs, q0, v0, R0, stride, _run_attrs(stride, inputs.project_v0, config, R0),
                          overwrite=overwrite)


def _check_outputs(out: Path | None, plot: Path | None, overwrite: bool, resume: bool) -> None:
    """Check --out and --plot (each writable, not the other) and hold them: one writer per output,
    a second `gni run` on it is refused now, not at the end."""
    # --resume may find the run finished: its file is then read back, not replaced
    if out is not None:
        check_output(out, "--out", overwrite or resume)
    if plot is not None:
        check_plot(plot, overwrite)
        if out is not None and same_file(out, plot):
            raise UsageError("--plot", f"{str(plot)!r} is also --out: choose another path for the figure")
    hold("--out", out)
    hold("--plot", plot)


def _streamed_chunk(inputs: _RunInputs, stride: int, chunk: int | None) -> int:
    """The steps per chunk of a streamed run (`chunk`, or by default chunks of
    :data:`~gnipy.streaming.DEFAULT_CHUNK_NODES` nodes); UsageError for what is not streamed."""
    from gnipy.simulate import MAX_STEPS

    if inputs.method == "reference":
        raise UsageError("--checkpoint-every", "the continuous reference is not streamed")
    if inputs.plot is not None:
        raise UsageError("--plot", "not available for streamed runs: plot from the file (gnipy.plots)")
    if stride > MAX_STEPS:
        raise UsageError("--save-every", f"at most {MAX_STEPS} steps between saved nodes in a streamed run "
                         f"(a chunk holds at most {MAX_STEPS} steps), got {stride}")
    if chunk is None:  # chunks of the default number of nodes, within the steps one chunk may hold
        from gnipy.streaming import DEFAULT_CHUNK_NODES

        chunk = stride * max(1, min(DEFAULT_CHUNK_NODES, MAX_STEPS // stride))
    return chunk


def _run_attrs(stride: int, project_v0: bool, config: Path | None, R0, **more) -> dict[str, Any]:
    """The attributes `gni run` adds to its file: the stride, --project-v0, the command, `more`,
    the config file and R0."""
    extra = {"save_every": stride, "project_v0": int(project_v0), "command": "gni run", **more}
    if config is not None:
        extra["config_file"] = str(config)
    if R0 is not None:
        extra["R0"] = list(R0)
    return extra


def _run_in_memory(spec, params, inputs: _RunInputs, q0, v0, R0, stride: int, extra: dict, *,
                   overwrite: bool) -> bool:
    """`gni run` in memory: simulate, write --out (and --plot) and report; returns whether the run
    is healthy."""
    from gnipy.analysis import exact_errors, invariant_drifts
    from gnipy.io import write_netcdf

    sol, v0_used, seconds = simulate_model(
        spec, params, inputs.method, q0, v0, inputs.h, inputs.steps, inputs.t_final, inputs.project_v0, stride, R0=R0
    )
    exact = exact_errors(spec, params, sol, q0, v0_used)
    drifts = invariant_drifts(spec, params, sol.q, sol.v, sol.R)
    written = []
    if inputs.out is not None:
        attrs = attrs_for(spec, params, sol, q0, v0_used, exact, drifts, extra)
        with writing("--out", inputs.out):
            write_netcdf(sol, inputs.out, attrs=attrs, overwrite=overwrite)
        written.append(str(inputs.out))
    if inputs.plot is not None:
        write_plot(sol, inputs.plot, overwrite, result_written=inputs.out is not None)
        written.append(str(inputs.plot))
    run_report("gni run", spec, params, sol, exact, drifts, seconds, ", ".join(written) or None)
    return sol.healthy


def simulate_model(spec, params, method, q0, v0, h, steps, t_final, project_v0, save_every, R0=None):
    """Run in memory; returns `(sol, v0_used, seconds)` (v0_used is the projected v0 with
    --project-v0). Runs of :data:`PROGRESS_STEPS` steps or more report their progress."""
    import gnipy
    from gnipy.simulate import resolve_steps

    system = spec.build(params)
    # the initial velocity actually used: G-orthogonally projected onto the constraints if asked
    _, v0_used = system.check(q0, v0, R0=R0, project_v0=project_v0)
    v0_used = tuple(float(x) for x in v0_used)
    n_steps = resolve_steps(h, steps, t_final)[1]
    t0 = time.perf_counter()
    what = f"{spec.name}: compiling and integrating with {method}"
    if n_steps >= PROGRESS_STEPS:
        with Progress("run", n_steps, "steps", description=what) as progress:
            sol = gnipy.simulate(system, method, q0, v0_used, R0=R0, h=h, steps=steps, t_final=t_final,
                                 save_every=save_every, progress=progress)
            sol.q.block_until_ready()
    else:
        with busy(what):
            sol = gnipy.simulate(system, method, q0, v0_used, R0=R0, h=h, steps=steps, t_final=t_final,
                                 save_every=save_every)
            sol.q.block_until_ready()
    return sol, v0_used, time.perf_counter() - t0


def run_streamed(spec, params, method, q0, v0, R0, h, steps, t_final, project, save_every, chunk, resume, out,
                 extra, *, overwrite: bool = False, yes: bool = False) -> bool:
    """`gni run` in chunks through :func:`gnipy.streaming.simulate_to_file`, with its progress;
    returns whether the run is healthy (or failed, which has its own exit code)."""
    from gnipy.streaming import simulate_to_file

    system = spec.build(params)
    _, v0_used = system.check(q0, v0, R0=R0, project_v0=project)
    extra = dict(extra, v0=[float(x) for x in v0_used], **origin_attrs(spec))
    t0 = time.perf_counter()
    total = steps if steps is not None else round(float(t_final) / float(h))
    with Progress("run", total, "steps", description=f"{spec.name} with {method}") as progress:
        # replacing an existing file: only with --overwrite (checked above, and again by the writer);
        # --yes lifts the writer's own bound on the size of the run (max_bytes=None)
        more = {"max_bytes": None} if yes else {}
        with writing("--out", out):
            result = simulate_to_file(
                system, method, q0, v0_used, R0=R0, path=out, h=h, steps=steps, t_final=t_final,
                save_every=save_every, chunk_steps=chunk, resume=resume, overwrite=overwrite, attrs=extra,
                progress=progress, **more,
            )
    streamed_report(spec, params, method, h, result, time.perf_counter() - t0, out)
    return result.healthy or bool(result.result)


def write_plot(sol, path: Path, overwrite: bool = False, plot=None, *, result_written: bool = True,
               **kwargs) -> None:
    """The figure of a run, written atomically after its result file (if any: `result_written`):
    by default :func:`gnipy.plots.plot_solution` (configuration path, energy error, constraint
    residual and, for the GNI family, the hidden momentum), else `plot(sol, path,
    overwrite=..., **kwargs)` (e.g. `gnipy.plots.plot_control`)."""
    if plot is None:
        from gnipy.plots import plot_solution as plot

    try:
        with writing("--plot", path):
            plot(sol, path, overwrite=overwrite, **kwargs)
    except WriteFailure as e:
        what = "the result file was written; the figure was not" if result_written else "the figure was not written"
        raise WriteFailure(f"{e} ({what})") from None
