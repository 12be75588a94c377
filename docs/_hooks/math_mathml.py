"""MkDocs hook: the maths of every page typeset at build time, as MathML.

`pymdownx.arithmatex` (generic mode) leaves each formula as `\\(...\\)` in a
`<span class="arithmatex">` (`\\[...\\]` in a `<div>` for display maths), for a renderer in the
browser. This hook converts each to MathML with latex2mathml (a pure-Python LaTeX-to-MathML
converter), which browsers render natively (MathML Core: Chromium 109+, Firefox, Safari): the site
needs no script and no network for its maths. A formula latex2mathml cannot convert fails the build
(with the page and the formula), so none is ever shown as raw TeX.

The API pages' docstrings go through the same Markdown extensions (mkdocstrings), so their maths is
converted too.
"""

from __future__ import annotations

import html
import re

from latex2mathml.converter import convert

_MATH = re.compile(r'<(span|div) class="arithmatex">(.*?)</\1>', re.S)
_DELIMITED = re.compile(r"^\s*\\[(\[]\s*(.*?)\s*\\[)\]]\s*$", re.S)

#: Commands the docs use that latex2mathml spells otherwise (applied before converting).
_REWRITES = [
    (re.compile(r"\\operatorname\{([^}]*)\}"), r"\\mathrm{\1}"),
    (re.compile(r"\\tfrac"), r"\\frac"),
    (re.compile(r"\\dfrac"), r"\\frac"),
]


def to_mathml(tex: str, display: bool) -> str:
    """The MathML of the TeX formula `tex` (without its delimiters)."""
    for pattern, replacement in _REWRITES:
        tex = pattern.sub(replacement, tex)
    if display and "\\\\" in tex and "\\begin" not in tex:  # lines of a display: one under another
        tex = "\\begin{gathered}" + tex + "\\end{gathered}"
    return convert(tex, display="block" if display else "inline")


def typeset(page_html: str, where: str = "") -> str:
    """`page_html` with every arithmatex formula replaced by its MathML."""

    def replace(m):
        kind, body = m.group(1), html.unescape(m.group(2))
        inner = _DELIMITED.match(body)
        tex = inner.group(1) if inner else body
        try:
            mathml = to_mathml(tex, display=kind == "div")
        except Exception as e:  # noqa: BLE001 - any converter failure fails the build, naming the formula
            raise ValueError(f"{where}: cannot typeset {tex!r}: {type(e).__name__}: {e}") from None
        return f'<{kind} class="arithmatex">{mathml}</{kind}>'

    return _MATH.sub(replace, page_html)


def on_page_content(html_text, page, config, files):  # noqa: ARG001 - the MkDocs hook's signature
    """Typeset the page's maths (MkDocs event)."""
    return typeset(html_text, page.file.src_uri)
