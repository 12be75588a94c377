"""MkDocs hook: a reference page per public module, generated from the package's source.

Each public module of gnipy (every module of src/gnipy but the command line's implementation,
`gnipy.cli`, whose commands the command-line guide documents, and `__main__`) gets a page
`api/modules/<module>.md` holding `::: <module>` (mkdocstrings renders its docstring and public
members), and `api/modules/index.md` lists them all with the first line of each docstring. The
module list is read from the source files (`ast`, nothing imported), so a new module gets its page
without an edit here. The topical API pages (api/*.md) link to these pages.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

from mkdocs.structure.files import File

#: Top-level packages whose modules are not public API (documented elsewhere).
EXCLUDED = ("gnipy.cli",)


def _source_root(config) -> Path:
    return Path(config.config_file_path).parent / "src" / "gnipy"


def public_modules(root: Path) -> dict[str, str]:
    """`{dotted module name: first line of its docstring}` for the public modules under `root`."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        parts = ["gnipy", *path.relative_to(root).with_suffix("").parts]
        if parts[-1] == "__init__":
            parts = parts[:-1]
        name = ".".join(parts)
        if parts[-1] == "__main__" or any(p.startswith("_") for p in parts[1:]):
            continue
        if any(name == e or name.startswith(e + ".") for e in EXCLUDED):
            continue
        doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
        out[name] = doc.strip().splitlines()[0] if doc.strip() else ""
    return out


#: Modules whose page is a topical page of their own (the package root: api/gnipy.md).
OWN_PAGES = {"gnipy": "../gnipy.md"}


def _page(name: str) -> str:
    return f"# {name}\n\n[All modules](index.md)\n\n::: {name}\n    options:\n      show_root_heading: false\n"


def _index(modules: dict[str, str]) -> str:
    lines = ["# Every module", "",
             "A page per public module of gnipy, generated from its docstrings (the command line's own "
             "modules, `gnipy.cli`, are documented by the [command-line guide](../../user-guide/cli.md)). "
             "The [API overview](../index.md) groups them by topic.", "",
             "| Module | What it holds |", "|---|---|"]
    for name, summary in modules.items():
        cell = summary.replace("|", "\\|")
        lines.append(f"| [`{name}`]({OWN_PAGES.get(name, name + '.md')}) | {cell} |")
    return "\n".join(lines) + "\n"


_LINK = re.compile(r"^- \[`(gnipy[\w.]*)`\]\(modules/\1\.md\)\s*$", re.M)


def on_page_markdown(markdown, page, config, files):  # noqa: ARG001 - the MkDocs hook's signature
    """On the topical API pages, a line `- [`gnipy.x`](modules/gnipy.x.md)` gets the first line of the
    module's docstring (MkDocs event)."""
    if not page.file.src_uri.startswith("api/") or page.file.src_uri.startswith("api/modules/"):
        return markdown
    modules = public_modules(_source_root(config))
    return _LINK.sub(lambda m: f"{m.group(0).rstrip()}: {modules.get(m.group(1), '')}", markdown)


def on_files(files, config):
    """Add the generated pages (MkDocs event)."""
    modules = public_modules(_source_root(config))
    files.append(File.generated(config, "api/modules/index.md", content=_index(modules)))
    for name in modules:
        if name in OWN_PAGES:
            continue
        files.append(File.generated(config, f"api/modules/{name}.md", content=_page(name)))
    return files
