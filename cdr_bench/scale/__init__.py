"""Scale-out on Ray: ``cdr-bench sweep``, ``cdr-bench evaluate --backend ray`` and an RLlib
``MultiAgentEnv`` adapter. Ray is an optional extra (``pip install "cdr-bench[ray]"``),
imported lazily by these modules only."""
