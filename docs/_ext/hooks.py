"""MkDocs hooks of the documentation site (mkdocs.yml ``hooks:``).

- The tutorial notebook ``docs/tutorial_vicon.ipynb`` is rendered as the page
  ``tutorial_vicon.md``: its Markdown cells as they are, its code cells as Python blocks (the
  notebook is kept without outputs; the test suite runs it).
- Citations by key (``[Xu2024]``, in the guides and the docstrings) link to their entry in
  ``references.md``, whose entries get the keys as anchors.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

from mkdocs.structure.files import File, Files

NOTEBOOK = "tutorial_vicon.ipynb"
REFERENCES = "references.md"
KEY = re.compile(r"^- \*\*\[([A-Za-z0-9]+)\]\*\*", re.MULTILINE)
# HTML split into what not to touch (tags, code, links) and the text in between.
UNTOUCHED = re.compile(r"(<code\b.*?</code>|<pre\b.*?</pre>|<a\b.*?</a>|<[^>]+>)", re.DOTALL)
_keys: list[str] = []


def notebook_markdown(path: Path) -> str:
    """The notebook's cells as one Markdown page."""
    cells = json.loads(path.read_text(encoding="utf-8"))["cells"]
    parts = []
    for cell in cells:
        source = "".join(cell["source"]).strip("\n")
        if not source:
            continue
        parts.append(source if cell["cell_type"] == "markdown" else f"```python\n{source}\n```")
    parts.insert(1, f"*This page is the notebook [`docs/{NOTEBOOK}`]({NOTEBOOK}); "
                    "open it in Jupyter anywhere in the repository to run it.*")
    return "\n\n".join(parts) + "\n"


def on_files(files: Files, config) -> Files:
    docs = Path(config["docs_dir"])
    files.append(File.generated(config, "tutorial_vicon.md", content=notebook_markdown(docs / NOTEBOOK)))
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
