"""IPPO agent (cdr-bench agent protocol): one shared actor for every controlled aircraft, trained
by ``cdr-bench train ippo`` (:mod:`cdr_bench.rl.mappo`; README.md beside this file).

``checkpoint.pt`` beside this file (or ``CDR_BENCH_CHECKPOINT``, e.g. ``seeds/2/checkpoint.pt``)
holds the actor's weights only (Linear+Tanh x layers, Linear -> 27 logits), read with
``torch.load(weights_only=True)``; the critic (on the aircraft's own observation) was used in
training only. Each aircraft decides on its own observation (decentralised execution).
Decision: argmax of the masked logits -- never a masked action -- computed on the fixed numeric
path of :mod:`cdr_bench.inference` (same bits on every x86-64 CPU; torch only reads the file):
:class:`cdr_bench.inference.CheckpointActorAgent`.
"""

from __future__ import annotations

from pathlib import Path

from cdr_bench.inference import CheckpointActorAgent


class Agent(CheckpointActorAgent):
    algorithm = "ippo"
    default_checkpoint = str(Path(__file__).with_name("checkpoint.pt"))
