"""Generated documentation parts: the env card (from :class:`cdr_bench.env.CDREnv`'s docstring)
and the scenario format (from the schema). The documentation site renders them when it is built
(``docs/_hooks.py``: the ``env-card`` and ``scenario-fields`` directives), so there is no copy
that could drift from the code.
"""

from __future__ import annotations

import inspect


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
