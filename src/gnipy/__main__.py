"""The `gni` command (and `python -m gnipy`): the command line of :mod:`gnipy.cli`, started here so
that an installation without the `cli` extra gets one line naming it instead of a traceback."""

import sys

from .extras import MissingExtra, check


def main() -> None:
    """Run the `gni` command; without its packages (typer, rich, matplotlib, xarray, netCDF4),
    print ``gni: gnipy's command line needs typer: pip install 'gnipy[cli]'`` and exit with 1."""
    try:
        check("typer", "rich", "matplotlib", "xarray", "netCDF4", extra="cli")  # found, not imported
        from .cli import app
    except MissingExtra as e:
        sys.exit(f"gni: {e}")
    app()


if __name__ == "__main__":
    main()
