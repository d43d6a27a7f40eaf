"""mkdocs hook: the site's first page is the user's guide, README.md, whose links are relative to
the repository's root: on the site, ``docs/X.md`` is the page ``X.md``, and a source file is
named, not linked."""

from __future__ import annotations

import re
from pathlib import Path

README = Path(__file__).resolve().parent.parent / "README.md"


def on_page_markdown(markdown: str, page, config, files) -> str:
    if page.file.src_uri != "index.md":
        return markdown
    guide = README.read_text().replace("](docs/", "](")
    return re.sub(r"\[(`[^`]+`)\]\((?!https?:)[^)]+\.py\)", r"\1", guide)
