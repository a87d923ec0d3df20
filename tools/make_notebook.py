"""Write a notebook (without outputs) from a plain-Python source with ``# %%`` cells.

Cells starting with ``# %% [markdown]`` are markdown (their lines' leading ``# `` is
removed). Usage: ``python tools/make_notebook.py notebooks/src/04_custom_gear_set.py``
writes ``notebooks/04_custom_gear_set.ipynb``.
"""

import sys
from pathlib import Path

import nbformat


def notebook(src: Path):
    """The notebook (an ``nbformat`` object) built from ``src``."""
    cells, kind, buf = [], None, []

    def flush():
        if kind is None:
            return
        text = "\n".join(buf).strip("\n")
        if kind == "markdown":
            text = "\n".join(line[2:] if line.startswith("# ") else line.lstrip("#") for line in text.splitlines())
            cells.append(nbformat.v4.new_markdown_cell(text))
        elif text:
            cells.append(nbformat.v4.new_code_cell(text))

    for line in src.read_text().splitlines():
        if line.startswith("# %%"):
            flush()
            kind, buf = ("markdown" if "[markdown]" in line else "code"), []
        else:
            buf.append(line)
    flush()
    return nbformat.v4.new_notebook(cells=cells, metadata={"kernelspec": {"name": "python3", "display_name": "Python 3",
                                                                         "language": "python"}})


def build(src: Path) -> Path:
    """Write ``notebooks/<stem>.ipynb`` from ``notebooks/src/<stem>.py``."""
    out = src.parent.parent / (src.stem + ".ipynb")
    nbformat.write(notebook(src), out)
    return out


if __name__ == "__main__":
    for arg in sys.argv[1:]:
        print(build(Path(arg)))
