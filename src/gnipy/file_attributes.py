"""The global attributes of gnipy's files, stated once for a result file (:mod:`gnipy.io`,
:meth:`gnipy.Solution.to_xarray`), a streamed run and a sweep store: the CF attributes
(:func:`cf_attributes`), the provenance (:func:`provenance`: gnipy's and JAX's versions, when
the file was created), and every attribute value in a form netCDF stores (:func:`attribute_value`).
"""

from __future__ import annotations

import datetime as _dt
import json
from collections.abc import Mapping
from typing import Any

from .schema import CONVENTIONS

__all__ = ["attribute_value", "cf_attributes", "jax_version", "provenance"]


def attribute_value(v):
    """A netCDF-compatible attribute value (numbers, strings, lists of numbers; others as JSON)."""
    import numpy as np

    if isinstance(v, bool):
        return int(v)
    if isinstance(v, (int, float, str, np.integer, np.floating)):
        return v
    if isinstance(v, (list, tuple, np.ndarray)):
        a = np.asarray(v)
        if a.dtype.kind in "iuf" and a.ndim == 1 and a.size:
            return a.astype(np.float64)
        if a.dtype.kind in "iuf":
            return json.dumps(a.tolist())
    if isinstance(v, Mapping):
        return json.dumps({str(k): (float(x) if isinstance(x, (int, float)) else str(x)) for k, x in v.items()})
    return str(v)


def cf_attributes(model: str, method: str, *, title: str | None = None, created: str | None = None) -> dict[str, str]:
    """The CF global attributes of a result of `model` with `method`: `Conventions`, `title`,
    `source` (gnipy and its version) and `history` (when and by what it was created)."""
    from .version import __version__

    created = created or _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    return {
        "Conventions": CONVENTIONS,
        "title": title or f"{model} integrated with {method}",
        "source": f"gnipy {__version__}",
        "history": f"{created} gnipy {__version__}: {method} run of {model}",
    }


def jax_version() -> str:
    """The version of JAX that is installed (`"unknown"` when it cannot be imported)."""
    try:
        import jax

        return str(jax.__version__)
    except Exception:  # pragma: no cover
        return "unknown"


def provenance(**extra) -> dict[str, Any]:
    """Base provenance attributes: gnipy and JAX versions and creation time (UTC), plus `extra`."""
    from .version import __version__

    attrs = {
        "gnipy_version": __version__,
        "jax_version": jax_version(),
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    }
    attrs.update(extra)
    return attrs
