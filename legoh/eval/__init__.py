"""Benchmark evaluation: the paper's metrics over episode records, and their tables.

- ``metrics``: SR, TC, TR, MEV, TTF, T2R, DW, FR as plain functions; Markdown / CSV tables.
- ``benchmark``: the protocol of ``conf/eval`` (``evaluate``, ``compare``).
- ``plots``: top-down pictures of robots' paths on their trails.
- ``cli``: ``mode=eval`` (``main(cfg, out_dir)``).

Nothing is imported here, so ``legoh.eval.metrics`` stays free of torch and matplotlib.
"""
