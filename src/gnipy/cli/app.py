"""The `gni` application: the typer app the commands register on, and its global options."""

from __future__ import annotations

import typer

__all__ = ["app", "main"]

app = typer.Typer(
    name="gni",
    help="Simulate nonholonomic mechanical systems with the Geometric Nonholonomic Integrator (GNI).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("gnipy")
    except Exception:  # not installed as a distribution: ask the package
        from gnipy import __version__

        return __version__


def _version_callback(value: bool):
    if value:
        typer.echo(f"gni (gnipy) {_version()}")
        raise typer.Exit()


@app.callback()
def main(
    version: bool = typer.Option(
        False, "--version", callback=_version_callback, is_eager=True, help="Print the gnipy version and exit."
    ),
):
    """Simulate nonholonomic mechanical systems with the Geometric Nonholonomic Integrator (GNI).

    With GNIPY_COMPILATION_CACHE=1 in the environment, compiled programs are kept in
    ~/.cache/gnipy/jax between runs ($GNIPY_CACHE_DIR to move it; a folder that is not yours alone,
    or a link, is refused with a warning). The native backend keeps its object code in
    ~/.cache/gnipy/native ($GNIPY_CACHE_DIR/native; GNIPY_NATIVE_CACHE=0 turns it off), each entry
    authenticated for this user and program.
    """
    import warnings

    from gnipy.compilation import cache_requested, enable_compilation_cache
    from gnipy.errors import QualitativeFailureWarning

    # the commands print the verdicts themselves (their warnings, the health row, exit code 3)
    warnings.simplefilter("ignore", QualitativeFailureWarning)
    if cache_requested():
        enable_compilation_cache()
