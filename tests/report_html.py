"""Reading the evaluation report's HTML in tests: its tables by section."""

from __future__ import annotations

from html.parser import HTMLParser


class PageTables(HTMLParser):
    """Tables of a page by the id of the ``<h2>`` before them: {section: [[row cells]]}."""

    def __init__(self):
        super().__init__()
        self.section = ""
        self.tables: dict[str, list[list[list[str]]]] = {}
        self.cell: list[str] | None = None
        self.row: list[str] | None = None

    def handle_starttag(self, tag, attrs):
        if tag == "h2":
            self.section = dict(attrs).get("id", "")
        elif tag == "table":
            self.tables.setdefault(self.section, []).append([])
        elif tag == "tr":
            self.row = []
        elif tag in ("td", "th"):
            self.cell = []

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self.cell is not None:
            self.row.append("".join(self.cell).strip())
            self.cell = None
        elif tag == "tr" and self.row is not None:
            self.tables[self.section][-1].append(self.row)
            self.row = None

    def handle_data(self, data):
        if self.cell is not None:
            self.cell.append(data)


def page_tables(text: str) -> dict:
    """Tables of an HTML page by the id of the ``<h2>`` before them (:class:`PageTables`)."""
    p = PageTables()
    p.feed(text)
    return p.tables


def as_dicts(table: list[list[str]]) -> dict[str, dict[str, str]]:
    """{first cell: {header: cell}} of a table whose first row is its header."""
    header, *rows = table
    return {r[0]: dict(zip(header, r, strict=True)) for r in rows}
