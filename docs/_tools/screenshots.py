"""Screenshots of the documentation site in a headless browser, with the network unreachable.

    python docs/_tools/screenshots.py --out screenshots/

builds the site (`mkdocs build --strict` into a temporary folder, or `--site DIR` to use a built
one), then opens three pages (the theory page, the guide to systems, and the reference page of
`gnipy.system`) in a headless Chromium whose every host name resolves to nothing
(`--host-resolver-rules`), and writes a PNG of each: what a reader sees offline, with the maths
(MathML, typeset when the site was built) and the highlighted code. Look at them: the formulas
must show as formulas, not as TeX. Needs Chromium (Debian: `apt install chromium-headless-shell`,
or `chromium`; `--browser PATH` names another); it is not part of the test suite, which checks
the built pages' HTML instead (tests/test_docs.py).
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

#: The pages shot: (site path, output name).
PAGES = [
    ("theory/index.html", "theory.png"),
    ("user-guide/systems/index.html", "systems.png"),
    ("api/modules/gnipy.system/index.html", "api-system.png"),
]

BROWSERS = ("chromium-headless-shell", "chromium", "chromium-browser", "google-chrome", "chrome")


def find_browser(name: str | None) -> str:
    """The browser to run: `name`, else the first of :data:`BROWSERS` on PATH."""
    for candidate in ([name] if name else BROWSERS):
        path = shutil.which(candidate)
        if path:
            return path
    sys.exit(f"screenshots: no headless browser found (tried {', '.join([name] if name else BROWSERS)}); "
             "install chromium-headless-shell or pass --browser PATH")


def build_site(folder: Path) -> Path:
    """Build the site into `folder`; returns it."""
    subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(ROOT / "mkdocs.yml"),
                    "--site-dir", str(folder)], check=True, cwd=ROOT)
    return folder


def shoot(browser: str, page: Path, png: Path, width: int = 1280, height: int = 1600) -> None:
    """Write a PNG of the local `page` as the browser shows it offline."""
    args = [browser, "--headless", "--disable-gpu", "--hide-scrollbars",
            "--host-resolver-rules=MAP * ~NOTFOUND",  # the network is unreachable: no host resolves
            f"--window-size={width},{height}", f"--screenshot={png}", page.as_uri()]
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        args.insert(1, "--no-sandbox")  # Chromium refuses to run as root with its sandbox
    subprocess.run(args, check=True, capture_output=True, timeout=120)
    if not png.is_file():
        sys.exit(f"screenshots: the browser wrote no {png}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("screenshots"), help="folder for the PNGs")
    parser.add_argument("--site", type=Path, default=None, help="a built site (default: build one now)")
    parser.add_argument("--browser", default=None, help="the browser's executable")
    args = parser.parse_args(argv)
    browser = find_browser(args.browser)
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        site = args.site or build_site(Path(tmp) / "site")
        for rel, name in PAGES:
            shoot(browser, (site / rel).resolve(), args.out / name)
            print(f"wrote {args.out / name} ({rel})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
