"""`python -m gnipy.cli`: the `gni` command."""

from . import app

app()
