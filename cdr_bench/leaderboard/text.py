"""Text a submission gives (display name, description, authors, reference, training command):
validated when the file is loaded, escaped for every page it reaches, compared for look-alikes.

* :func:`text_problems`: what is wrong with one free-text value (length, line breaks, control
  and invisible characters, the characters a name may use, script URLs), as messages;
* :func:`md_text`: a value as Markdown that renders exactly as the text (GitHub, MkDocs), every
  character that Markdown or raw HTML would interpret escaped; :func:`md_code` as a code span;
* :func:`skeleton`: the form two display names are compared in (Unicode NFKC, case folding,
  a small confusable map from Greek and Cyrillic letters to the Latin ones they look like,
  accents dropped): two entries whose names have the same skeleton are refused.

The HTML pages escape with :func:`html.escape` (``page_tables.esc``); their ``inline_md`` reads
the escapes :func:`md_text` writes, so one escaped cell renders the same on both pages.
"""

from __future__ import annotations

import re
import unicodedata

from cdr_bench.errors import short_repr

NAME_MAX = 64
"""Longest display name (characters)."""
DESCRIPTION_MAX = 400
"""Longest description."""
AUTHOR_MAX = 100
"""Longest author."""
AUTHORS_MAX = 32
"""Most authors."""
REFERENCE_MAX = 300
"""Longest reference (URL or path)."""
TRAINING_MAX = 500
"""Longest training command."""

NAME_PUNCTUATION = " -+()./,:'_"
"""What a display name may hold besides letters and digits (any script)."""

_INVISIBLE = {"Cc", "Cf", "Cs", "Co", "Cn", "Zl", "Zp"}
"""Unicode categories refused in every text: control, format (bidirectional overrides,
zero-width joiners), surrogates, private use, unassigned, line and paragraph separators."""

_SCRIPT_URL = re.compile(r"(?i)(javascript|vbscript)\s*:|data:[a-z]+/")


def text_problems(value: str, *, limit: int, name: bool = False) -> list[str]:
    """What is wrong with a one-line free-text value (empty when nothing), the most telling
    first: more than one line, a control or invisible character, a script URL
    (``javascript:``, ``vbscript:``, ``data:``); with ``name``, any character other than
    letters, digits and :data:`NAME_PUNCTUATION`, or a first character other than a letter or
    a digit; longer than ``limit``."""
    out = []
    if "\n" in value or "\r" in value or "\u2028" in value or "\u2029" in value:
        out.append("expected one line, got a line break")
    for i, ch in enumerate(value):
        if ch not in "\n\r" and unicodedata.category(ch) in _INVISIBLE:
            out.append(f"control or invisible character U+{ord(ch):04X} at position {i + 1}")
            break
    if name:
        bad = sorted({c for c in value if not (c.isalnum() or c in NAME_PUNCTUATION)})
        bad = [c for c in bad if unicodedata.category(c) not in _INVISIBLE]
        if bad:
            shown = " ".join(short_repr(c) for c in bad[:8])
            out.append(
                f"a name holds letters, digits, spaces and {NAME_PUNCTUATION.strip()} only; "
                f"got {shown}"
            )
        elif value and not value[0].isalnum():
            out.append(f"a name starts with a letter or a digit, got {short_repr(value[0])}")
    m = _SCRIPT_URL.search(value)
    if m:
        out.append(f"a script URL ({short_repr(m.group(0))}) is not allowed")
    if len(value) > limit:
        out.append(f"expected at most {limit} characters, got {len(value)}")
    return out


# ----------------------------------------------------------------------------------------------
# Markdown

_MD_BACKSLASH = set("\\`*[]{}")
"""Escaped with a backslash wherever they are (``{`` and ``}``: MkDocs' attribute lists)."""
_MD_ENTITY = {"&": "&amp;", "<": "&lt;", ">": "&gt;", "~": "&#126;", "^": "&#94;", "$": "&#36;"}
"""Written as entities: Python-Markdown reads no backslash escape of these (raw HTML;
strike-through, super/subscript and maths in Markdown extensions)."""
_MD_LINE_START = set("#+-=>!|")
"""Escaped at the start of the text only (block markers: heading, list, quote, table)."""


def md_text(value: str) -> str:
    """``value`` as Markdown text that renders as ``value`` itself: no emphasis, link, image,
    code, raw HTML, entity or block marker can come from it. ``_`` is escaped except between
    two letters or digits (where it never starts emphasis), ``|`` is left to the table writer
    (``md_table`` escapes it in cells). A line break (refused in submissions) becomes a space:
    text stays on its line of the page."""
    out = []
    for i, ch in enumerate(value):
        if ch in "\r\n\v\f\x1c\x1d\x1e\x85\u2028\u2029":
            out.append(" ")
        elif ch in _MD_ENTITY:
            out.append(_MD_ENTITY[ch])
        elif ch in _MD_BACKSLASH or (i == 0 and ch in _MD_LINE_START):
            out.append("\\" + ch)
        elif ch == "_":
            inner = 0 < i < len(value) - 1 and value[i - 1].isalnum() and value[i + 1].isalnum()
            out.append("_" if inner else "\\_")
        else:
            out.append(ch)
    return "".join(out)


def md_code(value: str) -> str:
    """``value`` as a Markdown code span (shown literally); a value holding a backtick, which
    would end the span, as escaped text instead."""
    return md_text(value) if "`" in value else f"`{value}`"


# ----------------------------------------------------------------------------------------------
# Look-alike names

CONFUSABLES = {
    **dict.fromkeys("ΑА", "A"), **dict.fromkeys("ΒВ", "B"), **dict.fromkeys("ΕЕ", "E"),
    **dict.fromkeys("Ζ", "Z"), **dict.fromkeys("ΗН", "H"), **dict.fromkeys("IΙІӀ1|", "l"),
    **dict.fromkeys("ΚК", "K"), **dict.fromkeys("ΜМ", "M"), **dict.fromkeys("Ν", "N"),
    **dict.fromkeys("ΟО0", "O"), **dict.fromkeys("ΡР", "P"), **dict.fromkeys("ΤТ", "T"),
    **dict.fromkeys("ΥҮУ", "Y"), **dict.fromkeys("ΧХ", "X"), **dict.fromkeys("СϹ", "C"),
    **dict.fromkeys("Ѕ", "S"), **dict.fromkeys("Ј", "J"), **dict.fromkeys("Ԍ", "G"),
    **dict.fromkeys("αа", "a"), **dict.fromkeys("βв", "b"), **dict.fromkeys("εе", "e"),
    **dict.fromkeys("ιіӏ", "i"), **dict.fromkeys("κк", "k"), **dict.fromkeys("νѵ", "v"),
    **dict.fromkeys("οо", "o"), **dict.fromkeys("ρр", "p"), **dict.fromkeys("τт", "t"),
    **dict.fromkeys("υ", "u"), **dict.fromkeys("χх", "x"), **dict.fromkeys("γу", "y"),
    **dict.fromkeys("ϲс", "c"), **dict.fromkeys("ѕ", "s"), **dict.fromkeys("ј", "j"),
    **dict.fromkeys("һ", "h"), **dict.fromkeys("ԁ", "d"), **dict.fromkeys("ԛ", "q"),
    **dict.fromkeys("ԝω", "w"), **dict.fromkeys("ɡ", "g"), **dict.fromkeys("ℓ", "l"),
    **dict.fromkeys("‐‑‒–—―−", "-"),
}  # fmt: skip
"""Greek and Cyrillic letters (and a few others) mapped to the Latin letter they look like, and
the Latin look-alikes ``I``/``1``/``|`` -> ``l``, ``0`` -> ``O``: a small hand-made subset of
Unicode's confusables (UTS #39), enough that a name cannot copy another by swapping scripts.
Compared after NFKC normalisation (full-width and styled letters are already plain there)."""


def skeleton(name: str) -> str:
    """The form display names are compared in: NFKC, the :data:`CONFUSABLES` map, case folding,
    accents dropped, ``rn`` read as ``m``, runs of spaces as one. Two names with the same
    skeleton look alike."""
    text = unicodedata.normalize("NFKC", name)
    text = "".join(CONFUSABLES.get(c, c) for c in text).casefold()
    text = "".join(c for c in unicodedata.normalize("NFD", text) if not unicodedata.combining(c))
    text = text.replace("rn", "m")
    return " ".join(text.split())
