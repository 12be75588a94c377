"""MkDocs hook: the code blocks' colours, from Pygments at build time.

The code blocks are highlighted when the site is built (`pymdownx.highlight` with Pygments, in
mkdocs.yml), not by highlight.js in the browser (which the built-in theme would load from a CDN).
This hook writes Pygments' stylesheet for those blocks to `css/pygments.css` in the site, and adds it
to the pages: the site needs no script and no network for its code.
"""

from __future__ import annotations

from pathlib import Path

from pygments.formatters import HtmlFormatter

#: The stylesheet's path in the site.
CSS = "css/pygments.css"


def on_config(config):
    """Link the stylesheet from every page (MkDocs event)."""
    if CSS not in config.extra_css:
        config.extra_css.append(CSS)
    return config


def on_post_build(config):
    """Write the stylesheet (MkDocs event)."""
    path = Path(config.site_dir) / CSS
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(HtmlFormatter(style="default").get_style_defs(".highlight"), encoding="utf-8")
