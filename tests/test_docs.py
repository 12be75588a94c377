"""The documentation: the site builds with `mkdocs build --strict` (every page, every API page
generated from the docstrings, every internal link and anchor). That its code runs as written is
tests/test_doc_examples.py."""

import pathlib
import re
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def test_site_builds_strict(tmp_path):
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocstrings_handlers.python")
    site = tmp_path / "site"
    # built with the network unreachable: every socket connection and name lookup of the build fails
    offline = (
        "import socket, runpy, sys\n"
        "def unreachable(*args, **kwargs):\n"
        "    raise OSError(101, 'Network is unreachable (tests/test_docs.py)')\n"
        "socket.socket.connect = socket.socket.connect_ex = unreachable\n"
        "socket.create_connection = socket.getaddrinfo = socket.gethostbyname = unreachable\n"
        "sys.argv = ['mkdocs', 'build', '--strict', '--config-file', sys.argv[1], '--site-dir', sys.argv[2]]\n"
        "runpy.run_module('mkdocs', run_name='__main__')\n"
    )
    res = subprocess.run(
        [sys.executable, "-c", offline, str(ROOT / "mkdocs.yml"), str(site)],
        cwd=ROOT, check=False, capture_output=True, text=True, timeout=300,
    )
    assert res.returncode == 0, res.stdout + res.stderr
    assert "WARNING" not in res.stderr, res.stderr
    pages = {str(page.relative_to(site)): page.read_text(encoding="utf-8") for page in sorted(site.rglob("*.html"))}
    # the site works offline: no page loads a script or a stylesheet from elsewhere
    external = re.compile(r"<(?:script|link)\b[^>]*\b(?:src|href)=[\"'](?:[a-z]+:)?//", re.I)
    assert [name for name, text in pages.items() if external.search(text)] == []
    # ... its maths is MathML, typeset when the site was built (docs/_hooks/math_mathml.py): no TeX
    # is left for a script to typeset
    raw_tex = re.compile(r'class="arithmatex">\s*\\[(\[]')
    assert [name for name, text in pages.items() if raw_tex.search(text)] == []
    theory = pages["theory/index.html"]
    assert theory.count("<math") > 20 and "mathvariant" in theory
    # ... and its code is coloured by Pygments at build time, with the stylesheet in the site
    assert '<span class="kn">import</span>' in pages["user-guide/systems/index.html"]
    assert (site / "css" / "pygments.css").is_file()
    assert [name for name, text in pages.items() if "\x00" in text] == []
    for page in ["index.html", "getting-started/index.html", "theory/index.html", "conventions/index.html",
                 "user-guide/cli/index.html",
                 "api/gnipy/index.html", "api/plots/index.html", "api/io/index.html", "api/lie_groups/index.html",
                 "api/retractions/index.html", "api/integrators/index.html", "api/models/index.html"]:
        assert (site / page).is_file(), page
    # the API pages hold the generated reference, not just their headings; signatures are formatted
    # one parameter a line (Black), not cut at the page's edge
    api = (site / "api" / "gnipy" / "index.html").read_text()
    for name in ["gnipy.System", "gnipy.simulate.simulate", "gnipy.Solution", "gnipy.get_model"]:
        assert f'id="{name}"' in api, name
    assert re.search(r"simulate</span><span class=\"p\">\(</span>\n\s+<span class=\"n\">system</span>", api), \
        "the signature of simulate is not formatted one parameter a line"
    # a page per public module (docs/_hooks/module_pages.py), listed on api/modules/
    modules = site / "api" / "modules"
    assert 'id="gnipy.plots.plot_convergence"' in (modules / "gnipy.plots" / "index.html").read_text()
    assert 'id="gnipy.io.write_netcdf"' in (modules / "gnipy.io" / "index.html").read_text()
    listed = set(re.findall(r'href="(gnipy[\w.]*)/"', (modules / "index.html").read_text()))
    sources = {".".join(["gnipy", *p.relative_to(ROOT / "src" / "gnipy").with_suffix("").parts]).removesuffix(".__init__")
               for p in (ROOT / "src" / "gnipy").rglob("*.py")
               if "cli" not in p.relative_to(ROOT / "src" / "gnipy").parts and p.name != "__main__.py"}
    assert listed == sources - {"gnipy"}, sorted(listed ^ (sources - {"gnipy"}))
    assert all((modules / name / "index.html").is_file() for name in listed)
    # no Sphinx role is left as text (docs/_hooks/sphinx_roles.py turns them into cross-references)
    roles = re.compile(r":(?:py:)?(?:mod|class|func|meth|data|attr|exc|obj|const|term):")
    literal = [str(page.relative_to(site)) for page in sorted(site.rglob("index.html"))
               if roles.search(page.read_text(errors="replace"))]
    assert literal == [], literal
    # ... a link where the object has an entry (`:mod:`gnipy.forcing`` in a docstring of gnipy's page)
    assert ('<a class="autorefs autorefs-internal" href="../modules/gnipy.forcing/#gnipy.forcing"><code>gnipy.forcing'
            '</code></a>') in api
    # the maths of every page, the docstrings of the API pages included, reached the typesetter intact
    mangled = [f"{page.relative_to(site)}: {problem}" for page in sorted(site.rglob("index.html"))
               for problem in rendered_math_problems(page.read_text())]
    assert mangled == [], "\n".join(mangled)


def _python_blocks(page: pathlib.Path) -> list[str]:
    return re.findall(r"```python\n(.*?)```", page.read_text(), flags=re.S)


def test_every_page_is_in_the_nav():
    nav = (ROOT / "mkdocs.yml").read_text()
    for page in DOCS.rglob("*.md"):
        assert str(page.relative_to(DOCS)) in nav, page


def test_cli_page_covers_every_command():
    from gnipy.cli import app

    text = (DOCS / "user-guide" / "cli.md").read_text()
    for command in app.registered_commands:
        name = command.name or command.callback.__name__
        assert f"gni {name}" in text, name


def test_getting_started_repeats_the_readme_quick_start():
    """The README's examples (run with every other block in tests/test_doc_examples.py) appear
    on the getting-started page as they are in the README."""
    readme = _python_blocks(ROOT / "README.md")
    page = _python_blocks(DOCS / "getting-started.md")
    assert readme and all(block in page for block in readme)


# ---------------------------------------------------------------------------------------------
# Maths on the pages. The build typesets (as MathML) what pymdownx.arithmatex protects: `$...$` inline and
# `$$...$$` display blocks. Anything else is Markdown, where `*` and `_` are emphasis: plain-text
# maths such as "p̄ = P*p⁺ + Q*Π" or "(b_k, p⁺_k): reflect to get p⁻_k; ... x_{k+1}" renders as
# "P<em>p⁺ + Q</em>Π" and "p⁺<em k_1>k): ... x</em>" (attr_list even reads "{k+1}" as attributes).
# math_problems needs no Markdown installed; test_page_renders_its_maths renders the pages.
# ---------------------------------------------------------------------------------------------

#: emphasis as prose writes it: opened at the start of a word (after a space, an opening bracket
#: or quote, or a dash), closed at its end; the content does not start or end with a space. (Markdown
#: also opens emphasis after a symbol, as in "p⁺_k ... p⁻_k": that is maths, and is left to be flagged.)
_EMPHASIS = re.compile(r"(?<![^\s(\[\"'“‘/—–-])(\*\*?)(?![\s*])(.+?)(?<![\s*\\])\1(?![\w*])"
                       r"|(?<![^\s(\[\"'“‘/—–-])(__?)(?![\s_])(.+?)(?<![\s_\\])\3(?![\w_])", flags=re.S)
_INLINE_MATH = re.compile(r"(?<![\\$])\$(?!\$)(.+?)(?<![\\$])\$(?!\$)", flags=re.S)


def _paragraphs(text: str):
    """The page's blocks between blank lines, as `(first line number, text)`, with fenced code
    blocks and inline code spans blanked out (their `$`, `*`, `_` are not Markdown)."""

    def blank(m):
        return re.sub(r"[^\n]", " ", m.group(0))

    text = re.sub(r"^([ \t]*)(```|~~~).*?^\1\2[^\n]*$", blank, text, flags=re.S | re.M)
    text = re.sub(r"(`+)(?!`).+?(?<!`)\1(?!`)", blank, text, flags=re.S)
    lines, out, start = text.split("\n"), [], None
    for i, line in enumerate([*text.split("\n"), ""], start=1):
        if line.strip() and start is None:
            start = i
        elif not line.strip() and start is not None:
            out.append((start, "\n".join(lines[start - 1:i - 1])))
            start = None
    return out


def math_problems(text: str) -> list[str]:
    """What would render mangled: math that arithmatex does not take, and maths-like prose that
    Markdown reads as emphasis. One message per problem, with its line number."""
    problems = []
    for line0, para in _paragraphs(text):
        where = f"line {line0}"
        if "$$" in para:
            body = para.strip()
            if not (para.startswith("$$") and body.endswith("$$") and body.count("$$") == 2):
                problems.append(f"{where}: a $$ display block must be a paragraph of its own, from '$$' at the "
                                f"start of a line after a blank line to '$$' before a blank line: {para[:60]!r}")
            continue
        table = [ln for ln in para.split("\n") if ln.lstrip().startswith("|")]
        prose = para
        for m in _INLINE_MATH.finditer(para):
            math = m.group(1)
            if math != math.strip():
                problems.append(f"{where}: inline math starts or ends with a space (arithmatex leaves it as "
                                f"text): ${math}$")
            if table and "|" in math:
                problems.append(f"{where}: '|' inside inline math in a table splits the cell (use \\vert): ${math}$")
            prose = prose.replace(m.group(0), " " * len(m.group(0)), 1)
        if "$" in prose.replace("\\$", ""):
            problems.append(f"{where}: an unbalanced '$' (inline math broken across a blank line?): {para[:60]!r}")
        # prose: emphasis pairs as Markdown reads them, then any '*' or '_' left is maths in plain text
        for m in _EMPHASIS.finditer(prose):
            prose = prose.replace(m.group(0), " " * len(m.group(0)), 1)
        prose = re.sub(r"^\s*\* ", "  ", prose, flags=re.M)  # list bullets
        for m in re.finditer(r"(?<!\\)\*", prose):
            if not (prose[m.start() - 1:m.start()].isspace() and prose[m.end():m.end() + 1].isspace()):
                ctx = prose[max(m.start() - 15, 0):m.end() + 15].replace("\n", " ")
                problems.append(f"{where}: '*' in plain-text maths (Markdown emphasis; write it as $...$): {ctx!r}")
        for m in re.finditer(r"(?<![\w\\])_", prose):
            ctx = prose[max(m.start() - 15, 0):m.end() + 15].replace("\n", " ")
            problems.append(f"{where}: '_' after a symbol in plain-text maths (Markdown emphasis; write it as "
                            f"$...$): {ctx!r}")
    return problems


def test_math_checker_catches_the_known_manglings():
    bad = {
        "reflection": "One step from (b_k, p⁺_k): reflect to get p⁻_k; solve x_{k+1}.\n",
        "stars": "it reports p̄ = P*p⁺ + Q*Π, which satisfies the constraints.\n",
        "display glued to text": "the transforms:\n$$p^-_k = FL^-$$\nwhere\n",
        "display in a list item's code block": "- item\n\n        $$x_1$$\n",
        "space before the closing dollar": "At node k: $b_k = $ the point.\n",
        "broken across a blank line": "the value $a_k\n\nb_k$ here\n",
        "bar in a table": "| a | b |\n|---|---|\n| $|x|$ | 1 |\n",
    }
    for name, text in bad.items():
        assert math_problems(text), name
    good = ("Plain words, *emphasis*, **bold (GNIred-1)**, x_k and R_{k+1} (safe after a letter), "
            "`p⁺_k * Q*` in code, $p^+_k = \\mathcal P^* p^-_k$ inline, and 3 * 4.\n\n"
            "$$\\bar p_k = \\mathcal P^* p^+_k + \\mathcal Q^*\\Pi(b_k),$$\n\n"
            "$$\na_k \\\\\nb_k\n$$\n\n| a | b |\n|---|---|\n| $x_k$ | *y* |\n\n```python\nx = a * b  # _k\n```\n")
    assert math_problems(good) == []


#: The theory page as it was: its central paragraph (the GNI step after (Comb)) and the errata's
#: "+2Q*Π", which rendered as "p⁺<em k_1>k): reflect to get p⁻<em k_1>k; ..." and "Q<em>Π"; ...".
OLD_THEORY = ("One step from (b_k, p⁺_k): reflect to get p⁻_k; solve FL⁻(x_k, x_{k+1}, R_k, σ_k) = p⁻_k for\n"
              "(x_{k+1}, σ_k); set R_{k+1} = R_k τ(σ_k); compute p⁺_{k+1} = FL⁺.\n\n"
              "- **(GNIredb-aff) and (RBb)** print \"+2Q*Π\"; the correct condition is\n"
              "  Q*((FL⁻ + FL⁺)/2 − Π) = 0, as in (GNIintAffb).\n")


def test_the_old_theory_page_is_caught():
    problems = math_problems(OLD_THEORY)
    assert any("line 1" in p and "'_'" in p for p in problems)
    assert any("line 4" in p and "'*'" in p for p in problems)


@pytest.mark.parametrize("page", sorted(str(p.relative_to(DOCS)) for p in DOCS.rglob("*.md")))
def test_page_maths_is_written_as_math(page):
    """Every maths span of the page is one arithmatex takes, and no plain-text maths holds a
    Markdown emphasis character."""
    assert math_problems((DOCS / page).read_text()) == []


def rendered_math_problems(html: str) -> list[str]:
    """What came out mangled in a rendered page: emphasis with attributes (attr_list reading
    "{k+1}"), emphasis around maths, and a `$` that arithmatex left as text."""
    problems = []
    for m in re.finditer(r"<(em|strong)([^>]*)>(.*?)</\1>", html, flags=re.S):
        words = re.sub(r"<[^>]*>", "", re.sub(r"<code\b.*?</code>", "", m.group(3), flags=re.S))
        if m.group(2).strip() or re.search(r"[*_^{}=+|\"⁺⁻ᵀ−×∘]", words):
            problems.append(f"emphasis around maths: {m.group(0)[:80]!r}")
    text = re.sub(r"<(div|span) class=\"arithmatex\">.*?</\1>", "", html, flags=re.S)
    text = re.sub(r"<(script|code|pre|style)\b.*?</\1>", "", text, flags=re.S)
    for m in re.finditer(r"(?<!\\)\$", text):
        problems.append(f"maths left as text: {text[max(m.start() - 30, 0):m.end() + 30]!r}")
    return problems


def _markdown_config():
    yaml = pytest.importorskip("yaml")
    pytest.importorskip("pymdownx.arithmatex")

    class Loader(yaml.SafeLoader):
        pass

    Loader.add_multi_constructor("", lambda loader, suffix, node: None)  # mkdocs' !!python/ tags
    config = yaml.load((ROOT / "mkdocs.yml").read_text(), Loader=Loader)
    names, configs = [], {}
    for ext in config["markdown_extensions"]:
        name, options = next(iter(ext.items())) if isinstance(ext, dict) else (ext, None)
        names.append(name)
        if options:
            configs[name] = options
    return names, configs


def _render(text: str) -> str:
    markdown = pytest.importorskip("markdown")
    names, configs = _markdown_config()
    return markdown.markdown(text, extensions=names, extension_configs=configs)


def test_rendered_checker_catches_the_old_theory_page():
    problems = rendered_math_problems(_render(OLD_THEORY))
    assert any("<em k_1>" in p for p in problems) and any("Π&quot;" in p or 'Π"' in p for p in problems), problems
    assert rendered_math_problems(_render("$p^+_k$ and **bold** and *word*\n\n$$\\bar p = P^*p^+$$\n")) == []


@pytest.mark.parametrize("page", sorted(str(p.relative_to(DOCS)) for p in DOCS.rglob("*.md")))
def test_page_renders_its_maths(page):
    """The page through Python-Markdown with the site's extensions (mkdocs.yml): no emphasis
    around maths and no maths left as text (the API pages' docstrings: test_site_builds_strict)."""
    assert rendered_math_problems(_render((DOCS / page).read_text())) == []


# ---------------------------------------------------------------------------------------------
# The package and its docs stand on their own: no pointer to the project's internal notes
# (DESIGN.md, the ../shared folder), which a user of the package never has. The conventions they
# held are on the docs' conventions page (docs/conventions.md).
# ---------------------------------------------------------------------------------------------

_INTERNAL = re.compile(r"\bDESIGN\b|\.\./shared|shared/(DESIGN|paper)")
_PUBLISHED = ["src", "docs", "examples", "benchmarks", "README.md", "BENCHMARKS.md", "mkdocs.yml", "pyproject.toml"]


def _published_files():
    for name in _PUBLISHED:
        path = ROOT / name
        files = [path] if path.is_file() else sorted(path.rglob("*"))
        for f in files:
            # build outputs (egg-info, caches) are generated, not written
            if f.is_file() and not any(part.endswith(".egg-info") or part == "__pycache__" for part in f.parts):
                yield f


def test_internal_notes_are_not_referenced():
    hits = []
    for f in _published_files():
        try:
            text = f.read_text()
        except UnicodeDecodeError:
            continue  # figures
        for i, line in enumerate(text.splitlines(), start=1):
            if _INTERNAL.search(line):
                hits.append(f"{f.relative_to(ROOT)}:{i}: {line.strip()[:100]}")
    assert hits == [], "references to the internal notes (say it on the docs' conventions page instead):\n" + \
        "\n".join(hits)
