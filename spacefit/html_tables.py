"""HTML tables of text cells, escaped: what Jupyter shows of spacefit's objects (their ``_repr_html_``)."""

from __future__ import annotations

import html
from collections.abc import Sequence
from typing import Any


def html_table(header: Sequence[str], rows: Sequence[Sequence[Any]], caption: str = "") -> str:
    """An HTML table of ``rows`` (cells as text, escaped) under ``header``, with a ``caption``."""
    cap = f"<caption style='text-align:left'>{html.escape(caption)}</caption>" if caption else ""
    head = "".join(f"<th style='text-align:left'>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td style='text-align:left'>{html.escape(str(c))}</td>" for c in row) + "</tr>"
                   for row in rows)
    return f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"
