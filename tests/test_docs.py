"""The documentation site (mkdocs.yml, docs/) builds in strict mode.

A broken link or anchor, a page missing from the navigation, or an API reference to a
name that no longer exists fails the build, and so this test. The reference pages are
generated from the docstrings of this checkout's ``jaxgear`` (``paths: [.]`` in
mkdocs.yml), not from whichever copy is installed.
"""

from __future__ import annotations

import ast
import html
import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
API = DOCS / "api"


def _documented() -> dict[str, Path]:
    """``{identifier: page}`` for every ``::: identifier`` line under docs/api/."""
    found = {}
    for page in sorted(API.glob("*.md")):
        for ident in re.findall(r"^:::\s+(\S+)", page.read_text(encoding="utf-8"), flags=re.M):
            found[ident] = page
    return found


def _built(site: Path, page: Path) -> Path:
    """The HTML file mkdocs writes for the markdown page ``page`` under docs/."""
    rel = page.relative_to(DOCS).with_suffix("")
    return site / (rel.parent if rel.name == "index" else rel) / "index.html"


def _page_text(path: Path) -> str:
    """The visible text of a built page: tags removed, entities decoded, spaces collapsed."""
    raw = path.read_text(encoding="utf-8")
    raw = re.sub(r"<(script|style)\b.*?</\1>", " ", raw, flags=re.S)
    return " ".join(html.unescape(re.sub(r"<[^>]+>", " ", raw)).split())


def _plain(markdown: str) -> str:
    """Docstring text as it reads once rendered: roles, links and code marks removed."""
    text = re.sub(r":\w+:`~?([^`]+)`", lambda m: m.group(1), markdown)
    text = re.sub(r"\[([^\]]*)\]\[[^\]]*\]", r"\1", text)
    return " ".join(text.replace("`", "").split())


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("site")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")  # keep the log to the build itself
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=600,
    )
    log = proc.stdout + proc.stderr
    if proc.returncode != 0:
        print(log)
    assert proc.returncode == 0, (
        "mkdocs build --strict failed (the docs tools come with pip install -e '.[test]'):\n" + log
    )
    return out


def test_site_builds_in_strict_mode(site):
    for page in ("index.html", "model/index.html", "methods/global-analysis/index.html",
                 "howto/cli/index.html", "api/global-analysis/index.html", "benchmarks/index.html"):
        assert (site / page).is_file(), page
    assert (site / "domains.png").is_file()


def test_api_page_shows_the_docstring(site):
    """The reference page of analyze_global holds the first line of its docstring."""
    import griffe  # required: mkdocstrings-python (the test extras) depends on it

    package = griffe.load("jaxgear", search_paths=[str(ROOT)], allow_inspection=False)
    first_line = package["analyze_global"].docstring.value.strip().splitlines()[0]
    page = _page_text(_built(site, _documented()["jaxgear.analyze_global"]))
    assert _plain(first_line) in page


def test_every_reference_is_rendered_once(site):
    """Each ``:::`` block renders its object under its own anchor, and no name is listed twice."""
    seen: dict[str, int] = {}
    for page in sorted(API.glob("*.md")):
        idents = re.findall(r"^:::\s+(\S+)", page.read_text(encoding="utf-8"), flags=re.M)
        built = _built(site, page).read_text(encoding="utf-8")
        for ident in idents:
            seen[ident] = seen.get(ident, 0) + 1
            assert f'id="{ident}"' in built, f"{ident} is not rendered on api/{page.name}"
        # docstrings read as intended: no raw Sphinx roles, no section titles left in the text
        text = _page_text(_built(site, page))
        assert not re.search(r":(class|func|meth|data|attr|mod):", text), page.name
        assert not re.search(r"<p>(Args|Returns|Raises|Attributes):", built), page.name
    assert not [i for i, n in seen.items() if n > 1], "listed on two reference pages"


def _exported(init: Path, prefix: str) -> set[str]:
    """Public names a package ``__init__`` re-exports (``from .x import a as a``) or defines."""
    tree = ast.parse(init.read_text(encoding="utf-8"))
    names = set()
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.level >= 1:
            names.update(a.asname for a in node.names if a.asname and a.asname == a.name)
        elif isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.add(node.name)
    return {f"{prefix}.{n}" for n in names if not n.startswith("_")}


def test_every_public_name_has_a_reference_entry():
    public = _exported(ROOT / "jaxgear" / "__init__.py", "jaxgear")
    public |= _exported(ROOT / "jaxgear" / "plotting" / "__init__.py", "jaxgear.plotting")
    missing = sorted(public - set(_documented()))
    assert not missing, f"add a '::: NAME' line for each to a page under docs/api/: {missing}"


def test_model_sections_are_numbered():
    """Code cites docs/model.md by section number: sections 1-8 keep their anchors."""
    text = (DOCS / "model.md").read_text(encoding="utf-8")
    for n in range(1, 9):
        assert re.search(rf"^## {n}\. .*\{{ #section-{n} \}}$", text, flags=re.M), f"model.md §{n}"


def test_no_machine_paths():
    """The repository stands alone: no page points outside it or to a local directory."""
    forbidden = ("../" + "shared", "/" + "work" + "/")  # split so this file does not match itself
    files = [ROOT / "mkdocs.yml"] + [p for p in DOCS.rglob("*") if p.is_file() and "__pycache__" not in p.parts]
    for path in files:
        data = path.read_bytes()
        for bad in forbidden:
            assert bad.encode() not in data, f"{path.relative_to(ROOT)} mentions {bad!r}"


def test_docstring_extension_rewrites():
    """The build's griffe extension: Sphinx roles, section spacing, model citations."""
    spec = importlib.util.spec_from_file_location("docs_ext", DOCS / "_ext" / "docstrings.py")
    ext = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ext)
    names = {"jaxgear.GearSet", "jaxgear.load", "jaxgear.plotting.plot_orbit"}
    text = "See :class:`GearSet`, :func:`~jaxgear.load`, :func:`jaxgear.plotting.plot_orbit` and :func:`_helper`."
    assert ext.rewrite_roles(text, names) == (
        "See [`GearSet`][jaxgear.GearSet], [`load`][jaxgear.load], "
        "[`jaxgear.plotting.plot_orbit`][jaxgear.plotting.plot_orbit] and `_helper`."
    )
    doc = "Summary.\n\nArgs:\n    x: a value.\nReturns:\n    y.\n"
    assert ext.separate_sections(doc) == "Summary.\n\nArgs:\n    x: a value.\n\nReturns:\n    y.\n"
    assert ext.separate_sections(ext.separate_sections(doc)) == ext.separate_sections(doc)
    assert ext.rewrite_model_refs("(docs/model.md §4) and docs/model.md §2-§4") == (
        "([model §4][section-4]) and [model §2–§4][section-2]"
    )
