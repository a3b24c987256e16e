"""The complete rig.json example of docs/capture-format.md, as the tests read it."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

DOCS = Path(__file__).resolve().parents[1] / "docs" / "capture-format.md"


def contract_example() -> dict[str, Any]:
    """The complete rig.json example of docs/capture-format.md."""
    text = DOCS.read_text(encoding="utf-8").split("A complete example", 1)[1]
    return json.loads(text.split("```json", 1)[1].split("```", 1)[0])
