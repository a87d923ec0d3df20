"""The documentation (README.md, CONTRIBUTING.md, mkdocs.yml, docs/) is checked like code.

The site builds in strict mode: a broken link or anchor, a page missing from the
navigation, or an API reference to a name that no longer exists fails the build, and so
these tests. The reference pages are generated from the docstrings of this checkout's
``jaxgear`` (``paths: [.]`` in mkdocs.yml), not from whichever copy is installed.

Every ```` ```python ```` block of the README and of the pages runs: the blocks of one
page in order, in one namespace, in a fresh folder, so a renamed or removed option fails
the suite instead of misleading a reader. Output excerpts use ```` ```text ```` or
```` ```console ````; a Python block that cannot run here (one process of a cluster job)
is preceded by ``<!-- not run: why -->``. Every ``--option`` of a ``jaxgear`` command in
the shell and output blocks is one that ``jaxgear <command> --help`` lists.
"""

from __future__ import annotations

import ast
import contextlib
import html
import importlib.util
import io
import os
import re
import subprocess
import sys
import textwrap
from dataclasses import dataclass
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
    return _build_site(tmp_path_factory.mktemp("site"))


def _build_site(out: Path, config: Path | None = None, execute: bool = False) -> Path:
    """``mkdocs build --strict`` into ``out`` (with ``config`` instead of mkdocs.yml);
    the notebooks are rendered without running them unless ``execute``."""
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1",  # keep the log to the build itself
               JAXGEAR_DOCS_EXECUTE="true" if execute else "false",
               # a notebook's kernel imports this checkout, with strict dtype promotion as every test
               PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
               JAX_NUMPY_DTYPE_PROMOTION="strict")
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)]
        + (["--config-file", str(config)] if config else []),
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=1200,
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


NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))


def _notebook_page(site: Path, notebook: Path) -> Path:
    return site / "notebooks" / notebook.stem / "index.html"


def test_every_notebook_is_a_page_of_the_site(site):
    """Each notebook is rendered (its first heading and its code), listed in the navigation,
    and downloadable; its paired script is not copied into the site."""
    import nbformat

    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    assert NOTEBOOKS
    for nb_path in NOTEBOOKS:
        nb = nbformat.read(nb_path, as_version=4)
        page = _notebook_page(site, nb_path)
        assert page.is_file(), f"{nb_path.name} has no page"
        text = _page_text(page)
        title = next(c.source for c in nb.cells if c.cell_type == "markdown").splitlines()[0].lstrip("# ")
        code = " ".join(next(c.source for c in nb.cells if c.cell_type == "code").splitlines()[0].split())
        assert title in text and code in text, nb_path.name
        assert f"notebooks/{nb_path.name}" in nav, f"{nb_path.name} is missing from the navigation"
        assert (page.parent / nb_path.name).is_file(), "no download of the notebook"
    assert not list((site / "notebooks").rglob("*.py")), "the paired scripts are not pages"


@pytest.mark.slow  # runs one notebook (about 1 min on two cores); the slow tier also runs each notebook itself
def test_the_site_shows_a_notebooks_outputs(tmp_path):
    """Built as published (JAXGEAR_DOCS_EXECUTE unset: true), a notebook's page holds what
    its cells printed and drew. One notebook is run here; the configuration inherits
    mkdocs.yml and leaves only the others unexecuted."""
    shown = ROOT / "notebooks" / "04_custom_gear_set.ipynb"
    import yaml

    class Loader(yaml.SafeLoader):
        pass

    Loader.add_constructor("!ENV", lambda loader, node: loader.construct_sequence(node)[-1])  # its default
    plugins = yaml.load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"), Loader)["plugins"]
    options = next(p["mkdocs-jupyter"] for p in plugins if isinstance(p, dict) and "mkdocs-jupyter" in p)
    assert options["execute"] is True, "the published site runs the notebooks"
    # INHERIT replaces a plugin's options whole: all of mkdocs.yml's, and the others not run
    options = dict(options, execute_ignore=[f"*/{p.name}" for p in NOTEBOOKS if p != shown])
    config = tmp_path / "mkdocs.yml"
    config.write_text(yaml.safe_dump({"INHERIT": str(ROOT / "mkdocs.yml"), "docs_dir": str(DOCS),
                                      "plugins": {"mkdocs-jupyter": options}}), encoding="utf-8")
    site = _build_site(tmp_path / "site", config, execute=True)
    figure, printed = re.compile(r'<img [^>]*src="data:image/png;base64'), "phases per planet: ["
    raw = _notebook_page(site, shown).read_text(encoding="utf-8")
    assert figure.search(raw), "no figure in the rendered notebook"
    assert printed in _page_text(_notebook_page(site, shown)), "no printed output in the rendered notebook"
    unexecuted = _notebook_page(site, NOTEBOOKS[0]).read_text(encoding="utf-8")
    assert not figure.search(unexecuted)  # the others were left unexecuted
    assert not (ROOT / ".cache").exists(), "the build wrote into the repository"


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


# --- the code in the documentation runs ------------------------------------------------

PAGES = sorted([ROOT / "README.md", ROOT / "CONTRIBUTING.md", *DOCS.rglob("*.md")])

SLOW_PAGES = {
    # page: why its examples run in the slow tier only. The default tier runs the README's
    # example and those that reuse its compiled analysis (the paper's region D in
    # 10 x 6 x 12 cells, the default method); each page below compiles programs of its
    # own (tens of seconds each) or integrates long.
    "docs/index.md": "the paper's cell map",
    "docs/howto/custom-gear-set.md": "a four-planet analysis",
    "docs/howto/own-system.md": "a user system analysed by every method, shooting, figures",
    "docs/howto/reproduce-paper.md": "the paper's full-size analyses (minutes)",
    "docs/howto/save-load.md": "shooting, figures, files",
    "docs/methods/attractors.md": "2,000-period Lyapunov runs and a 12-value backlash sweep",
    "docs/methods/continuation.md": "continuation and branch switching",
    "docs/methods/design.md": "40 gradient steps through a P-4 orbit",
    "docs/methods/global-analysis.md": "every method, the 4-D stroboscopic grid",
    "docs/methods/index.md": "a reference flow, shooting and RK4(400) analyses",
    "docs/methods/shooting.md": "orbit searches over periods 1 to 8",
    "docs/methods/sweeps.md": "bifurcation diagrams, basin sweeps and maps",
}

_FENCE = re.compile(
    r"^(?P<indent>[ \t]*)(?P<fence>`{3,})(?P<info>[^`\n]*)\n(?P<body>.*?)^(?P=indent)(?P=fence)[ \t]*$",
    flags=re.M | re.S,
)
_NOT_RUN = re.compile(r"<!--\s*not run:\s*(?P<why>[^>]*?)\s*-->\s*$")


@dataclass(frozen=True)
class Block:
    """One fenced code block: its language, first code line (1-based) and text."""

    lang: str
    line: int
    code: str
    not_run: str | None  # the reason given in a ``<!-- not run: ... -->`` line just above


def code_blocks(text: str) -> list[Block]:
    """The fenced code blocks of a markdown text (indented ones, in lists and admonitions, too)."""
    blocks = []
    for m in _FENCE.finditer(text):
        before = text[: m.start()].rstrip("\n").rsplit("\n", 1)[-1]
        why = _NOT_RUN.search(before)
        lang = (m.group("info").strip().split() or [""])[0].lstrip(".{").rstrip("}")
        blocks.append(Block(lang, text.count("\n", 0, m.start("body")) + 1,
                            textwrap.dedent(m.group("body")), why.group("why") if why else None))
    return blocks


def run_python_blocks(page: Path) -> int:
    """Run the ``python`` blocks of ``page`` in order in one namespace, in the current
    folder; an error propagates with the page and its line in the traceback. Returns the
    number of blocks run."""
    namespace = {"__name__": "__main__"}
    ran = 0
    for block in code_blocks(page.read_text(encoding="utf-8")):
        if block.lang not in ("python", "py") or block.not_run is not None:
            continue
        code = compile("\n" * (block.line - 1) + block.code, str(page), "exec")  # the page's line numbers
        exec(code, namespace)
        ran += 1
    return ran


def _page_id(page: Path) -> str:
    return str(page.relative_to(ROOT))


def _page_params():
    for page in PAGES:
        name = _page_id(page)
        if not page.is_file() or not any(b.lang in ("python", "py") for b in code_blocks(page.read_text("utf-8"))):
            continue
        marks = [pytest.mark.slow, pytest.mark.spread] if name in SLOW_PAGES else []
        yield pytest.param(page, id=name, marks=marks)


@pytest.fixture
def in_tmp_folder(tmp_path, monkeypatch):
    """A fresh working folder, the Agg backend for figures, and every figure closed after."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    monkeypatch.chdir(tmp_path)
    yield tmp_path
    import matplotlib.pyplot as plt

    plt.close("all")


@pytest.mark.parametrize("page", list(_page_params()))
def test_python_examples_run(page, in_tmp_folder):
    assert run_python_blocks(page) > 0


def test_readme_example_runs_in_the_default_tier():
    """The README's example is among the executed blocks, and not only in the slow tier."""
    blocks = [b for b in code_blocks((ROOT / "README.md").read_text("utf-8")) if b.lang == "python"]
    assert blocks and all(b.not_run is None for b in blocks)
    assert blocks[0].code.startswith("import jaxgear\njaxgear.enable_compilation_cache()")
    assert "README.md" not in SLOW_PAGES


def test_slow_pages_exist():
    assert all((ROOT / name).is_file() for name in SLOW_PAGES), "a page in SLOW_PAGES was moved"


def test_a_removed_option_in_an_example_fails(tmp_path, monkeypatch):
    """The runner fails on an example that passes an option that does not exist, at the
    page's own line, and runs neither output blocks nor blocks marked not run."""
    page = tmp_path / "page.md"
    page.write_text(textwrap.dedent('''\
        # A page

        ```text
        this is output, not code
        ```

        <!-- not run: one process of a cluster job -->
        ```python
        raise RuntimeError("a block marked not run was run")
        ```

        ```python
        import jaxgear
        grid = jaxgear.CellGrid.paper(counts=(4, 3, 5))
        ```

        !!! note
            ```python
            result = jaxgear.analyze_global(grid=grid, pilot=True)
            ```
        '''), encoding="utf-8")
    assert [b.lang for b in code_blocks(page.read_text("utf-8"))] == ["text", "python", "python", "python"]
    monkeypatch.chdir(tmp_path)
    with pytest.raises(TypeError, match="pilot") as info:
        run_python_blocks(page)
    assert any(entry.path == page and entry.lineno + 1 == 19 for entry in info.traceback)
    page.write_text(page.read_text("utf-8").replace(", pilot=True", ", progress=True, uncertainty=-1"))
    with pytest.raises(ValueError, match="uncertainty"):
        run_python_blocks(page)


# --- every option of a jaxgear command in the documentation exists --------------------

_COMMAND = re.compile(r"(?:^|[\s$;&|(])jaxgear\s+(params|analyze|shoot|sweep)\b(?P<rest>[^\n]*)")


def _documented_options(pages=PAGES) -> dict[tuple[str, str], list[str]]:
    """``{(command, --option): [page:line, ...]}`` for every ``jaxgear <command> ... --option``
    in the shell and output blocks and the inline code of ``pages`` (the README and the pages)."""
    found: dict[tuple[str, str], list[str]] = {}
    for page in pages:
        if not page.is_file():
            continue
        text = page.read_text(encoding="utf-8")
        spans = [(b.line, b.code) for b in code_blocks(text) if b.lang in ("bash", "sh", "console", "text", "")]
        inline = [(n + 1, code) for n, line in enumerate(text.split("\n")) for code in re.findall(r"`([^`\n]+)`", line)]
        for first, code in spans + inline:
            for offset, line in enumerate(code.replace("\\\n", " ").split("\n")):  # continued lines joined
                for m in _COMMAND.finditer(line):
                    rest = m.group("rest").split("#")[0]
                    for option in re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", rest):
                        found.setdefault((m.group(1), option), []).append(f"{page.name}:{first + offset}")
    return found


def _help_options(command: str) -> set[str]:
    from jaxgear.cli import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit):
        main([command, "--help"])
    return set(re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", out.getvalue()))


def _unknown_options(documented) -> dict[str, list[str]]:
    known = {cmd: _help_options(cmd) for cmd in {cmd for cmd, _ in documented}}
    return {f"jaxgear {cmd} {opt}": where for (cmd, opt), where in documented.items() if opt not in known[cmd]}


def test_documented_command_options_exist():
    documented = _documented_options()
    assert ("analyze", "--out") in documented  # the collector sees the README's set-up line
    assert ("sweep", "--values2") in documented  # and the other commands' (docs/howto/cli.md)
    wrong = _unknown_options(documented)
    assert not wrong, f"options that `jaxgear <command> --help` does not list: {wrong}"


def test_a_removed_command_option_is_found(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("Run `jaxgear analyze --pilot 1024`, or:\n\n```bash\njaxgear shoot --random 8 \\\n"
                    "    --damping 0.5 --out x   # --not-this-one\n```\n", encoding="utf-8")
    assert _unknown_options(_documented_options([page])) == {
        "jaxgear analyze --pilot": ["page.md:1"], "jaxgear shoot --damping": ["page.md:4"]}
