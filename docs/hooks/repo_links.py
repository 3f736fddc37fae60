"""mkdocs hook (mkdocs.yml): links from a page of docs/ to a file of the repository outside docs/.

The pages are read on GitHub too, where ``[tests/test_x.py](../tests/test_x.py)`` opens the file; the
site has no such file. This hook checks that the target exists in the repository (a warning otherwise,
which fails ``mkdocs build --strict``) and writes the link as a link into the repository at ``repo_url``
when mkdocs.yml sets one, else as the file's path in code. Links within docs/ are left to mkdocs's own
validation.
"""
from __future__ import annotations

import logging
import re
from pathlib import Path

log = logging.getLogger("mkdocs.hooks.repo_links")
LINK = re.compile(r"(?<!!)\[([^\]\n]+)\]\(([^)\s]+)\)")


def repo_link(text: str, target: str, page_dir: Path, docs: Path, repo_url: str | None, page: str) -> str | None:
    """The replacement of one link, or None to leave it as it is."""
    if "://" in target or target.startswith(("#", "mailto:")):
        return None
    path = target.split("#")[0]
    if not path:
        return None
    resolved = (page_dir / path).resolve()
    if resolved.is_relative_to(docs):
        return None
    root = docs.parent
    if not resolved.is_relative_to(root) or not resolved.exists():
        log.warning(f"Doc file '{page}' links to '{target}', which is not a file of the repository")
        return None
    rel = resolved.relative_to(root).as_posix()
    if repo_url:
        return f"[{text}]({repo_url.rstrip('/')}/blob/main/{rel})"
    return f"`{rel}`" if text.strip("`") == rel else f"{text} (`{rel}`)"


def on_page_markdown(markdown, page, config, files):
    docs = Path(config["docs_dir"]).resolve()
    page_dir = (docs / page.file.src_uri).parent

    def swap(m):
        new = repo_link(m.group(1), m.group(2), page_dir, docs, config.get("repo_url"), page.file.src_uri)
        return m.group(0) if new is None else new

    return LINK.sub(swap, markdown)
