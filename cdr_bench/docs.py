"""Generated documentation: the env card (from :class:`cdr_bench.env.CDREnv`'s docstring) and the
scenario format (from the schema) are written into README.md between markers, so the docs cannot
drift from the code. ``python -m cdr_bench.docs`` rewrites them; a test checks they are current.
"""

from __future__ import annotations

import inspect
import re
import sys
from collections.abc import Callable
from pathlib import Path

MARKERS: dict[str, Callable[[], str]] = {
    "env-card": lambda: env_card(),
    "scenario-fields": lambda: scenario_fields(),
}


def env_card() -> str:
    from cdr_bench.env import CDREnv

    doc = inspect.cleandoc(CDREnv.__doc__ or "")
    body = doc.split("\n", 1)[1].strip()
    return body.replace("## ", "#### ")


def scenario_fields() -> str:
    from cdr_bench.scenarios import field_docs

    rows = ["| field | type | meaning [range] |", "|---|---|---|"]
    for path, tp, doc in field_docs():
        rows.append(f"| `{path}` | {tp} | {doc.replace('|', '/')} |")
    return "\n".join(rows)


def render(text: str) -> str:
    for name, fn in MARKERS.items():
        pattern = re.compile(
            rf"(<!-- {name}:start -->\n)(.*?)(<!-- {name}:end -->)", flags=re.DOTALL
        )
        body = fn().replace("\\", "\\\\")
        text = pattern.sub(rf"\g<1>{body}\n\g<3>", text)
    return text


def main(argv: list[str] | None = None) -> int:
    path = Path(argv[0] if argv else "README.md")
    text = path.read_text()
    new = render(text)
    if new != text:
        path.write_text(new)
        print(f"updated {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
