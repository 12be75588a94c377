"""Matrix Lie groups: SO(3), SE(2), $\\mathbb{R}^n$, products and the trivial group.

Part of the core of the package (the docs' conventions page, "Architecture"). A group is a small
`equinox.Module` with static fields only; an element is a plain $k\\times k$ matrix and a Lie-algebra element a vector $\\xi\\in\\mathbb{R}^d$
(its matrix is $\\hat\\xi$). Every function is written for one unbatched element (use `jax.vmap` for
batches), in float64, and is `jit`/`vmap`/`grad` friendly.

Conventions (paper §7 and Appendix; the docs' conventions page):

- `hat`/`vee` identify $\\mathbb{R}^d$ with $\\mathfrak g$; for SO(3) `hat` is the paper's (hatso),
  $\\hat\\omega\\rho = \\omega\\times\\rho$.
- $\\mathrm{Ad}_g\\eta = (g\\hat\\eta g^{-1})^\\vee$, $\\mathrm{ad}_\\xi\\eta = [\\hat\\xi,\\hat\\eta]^\\vee$, and
  $\\mathrm{ad}^*_\\xi m = \\mathrm{ad}_\\xi^T m$ (for SO(3): $\\mathrm{ad}^*_\\omega M = M\\times\\omega$).
- `exp` and `log` are closed forms that are *safe at zero* in the style of jaxlie: near the
  identity a Taylor branch is selected with a "safe" `jnp.where` (the closed-form branch is fed a
  harmless dummy argument there), so neither values nor gradients (of any order) become NaN.

The base class :class:`MatrixLieGroup` implements every operation generically from `hat`, `vee` and
the basis of generators (`exp` by `jax.scipy.linalg.expm`); the concrete groups override them with
closed forms. Each group owns its retraction maps (paper, Appendix): the Cayley map and the
exponential, their inverses and their (inverse) right-trivialized tangents, which
:mod:`gnipy.retractions` only calls; a new group is one file (see :mod:`gnipy.lie_groups.base`).
"""

# The package's modules: `series` (even functions of an angle, safe at zero, and the paper's
# series of dexp), `base` (MatrixLieGroup and the argument checks), `so3`, `se2`, `abelian`
# (Rn, TrivialGroup) and `product` (ProductGroup). The names are imported in the order the API
# page lists them.
from .base import MatrixLieGroup
from .so3 import SO3
from .se2 import SE2
from .abelian import Rn, TrivialGroup
from .product import ProductGroup
from .series import (
    sinc_sq,
    cos_sq,
    one_minus_cos_sq,
    theta_minus_sin_sq,
    dexp_inv_coefficient_sq,
    half_cot_half_sq,
)

__all__ = [
    "SE2",
    "SO3",
    "MatrixLieGroup",
    "ProductGroup",
    "Rn",
    "TrivialGroup",
    "cos_sq",
    "dexp_inv_coefficient_sq",
    "half_cot_half_sq",
    "one_minus_cos_sq",
    "sinc_sq",
    "theta_minus_sin_sq",
]
