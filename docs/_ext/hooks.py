"""MkDocs hooks of the documentation site (mkdocs.yml ``hooks:``).

- The tutorial notebook ``docs/tutorial_vicon.ipynb`` (kept without outputs) is executed at each
  build in a Jupyter kernel of the building Python (nbclient; its exports to a temporary folder)
  and rendered as the page ``tutorial_vicon.md`` with its outputs (nbconvert's Markdown exporter:
  printed text, tables, the figures as PNG files beside the page). A cell that raises fails the
  build.
- Citations by key (``[Xu2024]``, in the guides and the docstrings) link to their entry in
  ``references.md``, whose entries get the keys as anchors.
"""

from __future__ import annotations

import os
import re
import tempfile
from pathlib import Path
from unittest.mock import patch

from mkdocs.structure.files import File, Files

NOTEBOOK = "tutorial_vicon.ipynb"
KERNEL_TIMEOUT_S = 600
"""Longest a notebook cell may run (s)."""
REFERENCES = "references.md"
KEY = re.compile(r"^- \*\*\[([A-Za-z0-9]+)\]\*\*", re.MULTILINE)
# HTML split into what not to touch (tags, code, links) and the text in between.
UNTOUCHED = re.compile(r"(<code\b.*?</code>|<pre\b.*?</pre>|<a\b.*?</a>|<[^>]+>)", re.DOTALL)
_keys: list[str] = []


def executed_notebook(path: Path) -> tuple[str, dict[str, bytes]]:
    """The notebook run top to bottom in a fresh kernel (cwd its folder), as Markdown with its
    outputs, and the output images by file name (under ``<stem>_files/``)."""
    import nbformat
    from nbclient import NotebookClient
    from nbconvert import MarkdownExporter

    notebook = nbformat.read(path, as_version=4)
    with tempfile.TemporaryDirectory(prefix="bodyfusion-tutorial-") as out:
        client = NotebookClient(notebook, timeout=KERNEL_TIMEOUT_S, kernel_name="python3",
                                resources={"metadata": {"path": str(path.parent)}})
        with patch.dict(os.environ, BODYFUSION_TUTORIAL_OUT=out):  # the kernel inherits it
            client.execute()
    body, resources = MarkdownExporter().from_notebook_node(
        notebook, resources={"output_files_dir": f"{path.stem}_files"})
    preface = (f"*This page is the notebook [`docs/{path.name}`]({path.name}), run as the site was built; "
               "open it in Jupyter anywhere in the repository to run it.*")
    title, _, rest = body.partition("\n\n")
    return f"{title}\n\n{preface}\n\n{rest}", resources.get("outputs", {})


def on_files(files: Files, config) -> Files:
    docs = Path(config["docs_dir"])
    page, images = executed_notebook(docs / NOTEBOOK)
    files.append(File.generated(config, "tutorial_vicon.md", content=page))
    for name, content in images.items():
        files.append(File.generated(config, name, content=content))
    _keys[:] = KEY.findall((docs / REFERENCES).read_text(encoding="utf-8"))
    return files


def _anchor(key: str) -> str:
    return "ref-" + key.lower()


def on_page_content(html: str, page, config, files: Files) -> str:
    if not _keys:
        return html
    cite = re.compile(r"\[(" + "|".join(map(re.escape, _keys)) + r")\]")
    if page.file.src_uri == REFERENCES:
        # The entries' keys (<strong>[Key]</strong>) become their anchors.
        return re.sub(r"<strong>\[(" + "|".join(map(re.escape, _keys)) + r")\]</strong>",
                      lambda m: f'<strong id="{_anchor(m.group(1))}">[{m.group(1)}]</strong>', html)
    target = files.get_file_from_path(REFERENCES).url_relative_to(page.file)

    def link(text: str) -> str:
        return cite.sub(lambda m: f'<a href="{target}#{_anchor(m.group(1))}">[{m.group(1)}]</a>', text)

    return "".join(part if UNTOUCHED.fullmatch(part) else link(part) for part in UNTOUCHED.split(html))
