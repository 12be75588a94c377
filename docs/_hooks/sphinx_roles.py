"""MkDocs hook: the Sphinx roles of gnipy's docstrings as cross-references.

gnipy's docstrings name other objects the way Sphinx does (:func:`gnipy.simulate`,
:class:`~gnipy.Solution`, :mod:`gnipy.monitor`); mkdocstrings renders them as text, so the API
pages showed the roles literally (`:func:gnipy.simulate`). This hook turns each rendered role into
an optional mkdocs-autorefs reference: a link where the object has a page, its plain name
otherwise (`~` shows the last component only, as in Sphinx). Written here because neither
mkdocstrings-python nor griffe converts Sphinx roles in Google-style docstrings.
"""

from __future__ import annotations

import html
import re

#: A rendered role: `:func:` followed by the code span mkdocstrings made of its target.
ROLE = re.compile(r":(?:py:)?(?:mod|class|func|meth|data|attr|exc|obj|const|term):<code>(?P<tilde>~?)"
                  r"(?P<target>[A-Za-z_][\w.]*)(?P<call>\(\))?</code>")


def _reference(m: re.Match) -> str:
    target = m["target"]
    shown = target.rsplit(".", 1)[-1] if m["tilde"] else target
    shown += m["call"] or ""
    return f'<autoref identifier="{html.escape(target)}" optional><code>{html.escape(shown)}</code></autoref>'


def on_page_content(html_text: str, **kwargs) -> str:
    """Replace every rendered Sphinx role of the page by an optional cross-reference."""
    return ROLE.sub(_reference, html_text)
