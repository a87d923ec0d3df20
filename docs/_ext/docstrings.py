"""Griffe extension used by the documentation build (see ``mkdocs.yml``).

jaxgear's docstrings follow the Google style with two habits that the Google parser of
griffe does not read as intended. This extension adjusts the docstring text before it
is parsed; it changes nothing in the package.

1. Sphinx roles such as ``:class:`GearSet``` or ``:func:`~jaxgear.load``` become
   cross-references to the reference page of that name when the name is documented
   under ``docs/api/`` (a ``::: jaxgear.NAME`` line), and plain code otherwise (private
   helpers, methods, constants, other packages).
2. A section title (``Returns:``, ``Raises:``, ...) written directly under the previous
   section, without a blank line, gets one: griffe only starts a section after a blank
   line and would otherwise print the title and its contents as running text.
3. A citation of the model document, ``docs/model.md §4`` (or the older ``MODEL.md §4``,
   also ranges such as ``§2-§4``), becomes a link to that section of the model page.

Both rewrites are idempotent and do nothing to a docstring already written in plain
Google style, so the extension can stay when the docstrings change.
"""

from __future__ import annotations

import re
from pathlib import Path

import griffe

API_DIR = Path(__file__).resolve().parent.parent / "api"

_ROLE = re.compile(r":(?:py:)?(?:class|func|meth|data|attr|mod|obj|exc|const):`(~?)([^`<>]+?)(?:\(\))?`")
_SECTION = re.compile(
    r"(Args|Arguments|Parameters|Params|Keyword Args|Keyword Arguments|Other Parameters|"
    r"Returns|Return|Yields|Yield|Receives|Raises|Raise|Exceptions|Warns|Warnings|"
    r"Attributes|Functions|Methods|Classes|Modules|Examples?|Notes?)\s*:\s*"
)


_MODEL_REF = re.compile(r"(?<![\w/.\[])(?:docs/)?(?:MODEL|model)\.md ?§(\d+)((?:\.\d+)?(?:\s*[-–]\s*§?\d+(?:\.\d+)?)?)")


def documented_names(api_dir: Path = API_DIR) -> set[str]:
    """Identifiers that have a ``::: identifier`` block on some reference page."""
    names: set[str] = set()
    for page in sorted(api_dir.glob("*.md")):
        names.update(re.findall(r"^:::\s+(\S+)", page.read_text(encoding="utf-8"), flags=re.M))
    return names


def _candidates(target: str) -> list[str]:
    if target.startswith("jaxgear."):
        last = target.rsplit(".", 1)[-1]
        # a private module path (jaxgear._params.with_param) names a re-exported object
        return [target, f"jaxgear.{last}", f"jaxgear.plotting.{last}"]
    return [f"jaxgear.{target}", f"jaxgear.plotting.{target}"]


def rewrite_roles(text: str, names: set[str]) -> str:
    """Replace Sphinx roles by cross-references (documented names) or code."""

    def repl(match: re.Match) -> str:
        tilde, target = match.group(1), match.group(2).strip()
        shown = target.rsplit(".", 1)[-1] if tilde else target
        for ident in _candidates(target):
            if ident in names:
                return f"[`{shown}`][{ident}]"
        return f"`{shown}`"

    return _ROLE.sub(repl, text)


def rewrite_model_refs(text: str) -> str:
    """Turn ``MODEL.md §4`` / ``docs/model.md §2-§4`` into a link to that model section."""

    def repl(match: re.Match) -> str:
        first, rest = match.group(1), match.group(2)
        rest = re.sub(r"\s*[-–]\s*§?", "–§", rest)
        return f"[model §{first}{rest}][section-{first}]"

    return _MODEL_REF.sub(repl, text)


def separate_sections(text: str) -> str:
    """Put a blank line above every section title that follows text directly."""
    lines = text.split("\n")
    out: list[str] = []
    for i, line in enumerate(lines):
        below = lines[i + 1] if i + 1 < len(lines) else ""
        if (_SECTION.fullmatch(line) and out and out[-1].strip()
                and below.startswith((" ", "\t")) and below.strip()):
            out.append("")
        out.append(line)
    return "\n".join(out)


class SphinxRolesAndSections(griffe.Extension):
    """Adjust every docstring of the loaded package before it is parsed."""

    def __init__(self) -> None:
        super().__init__()
        self.names = documented_names()

    def _fix(self, obj: griffe.Object) -> None:
        seen: set[int] = set()
        stack = [obj]
        while stack:
            o = stack.pop()
            if id(o) in seen or o.is_alias:
                continue
            seen.add(id(o))
            if o.docstring is not None:
                o.docstring.value = separate_sections(rewrite_model_refs(rewrite_roles(o.docstring.value, self.names)))
            stack.extend(m for m in o.members.values() if not m.is_alias)

    def on_package(self, *, pkg: griffe.Module, **kwargs) -> None:  # griffe >= 1.14
        self._fix(pkg)

    def on_package_loaded(self, *, pkg: griffe.Module, **kwargs) -> None:  # older griffe
        self._fix(pkg)
