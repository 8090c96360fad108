"""The leaderboard: submissions, their result files, the published numbers and the pages built
from them (``cdr-bench leaderboard build``).

Layout of a leaderboard folder (``leaderboard/`` in the repository)::

    submissions/<name>.yaml      one entry each: agent, checkpoint, authors, reference, training
                                 command, scenarios (see :mod:`.submission`)
    results/<name>.json|.jsonl.xz   written by ``cdr-bench evaluate`` (run by ``build --evaluate``)
    results/<name>.multimodal-<scenario>.json   written by ``cdr-bench multimodal`` (optional)
    results/<name>.replays.json  trajectories of the first episodes of the scenarios the entry
                                 replays (``replays``; recorded by the scorer, :mod:`.entry`)
    published/table2.yaml, table3.yaml          the paper's numbers, verbatim (:mod:`.published`)
    README.md, index.html, plots/*.png          generated; never edited by hand

Paths in a submission are relative to the folder that holds the leaderboard folder (the
repository root). Rendering reads result files (and the training logs the submissions name)
only (the ranking: :mod:`.data`; the pages: :mod:`.render`); evaluation runs every submission
in its own sandboxed process (:mod:`.sandbox`); ``--check`` re-evaluates and compares
(:mod:`.build`).
"""

from __future__ import annotations

from cdr_bench.leaderboard.submission import Submission, SubmissionError, load_submissions

__all__ = ["Submission", "SubmissionError", "load_submissions"]
