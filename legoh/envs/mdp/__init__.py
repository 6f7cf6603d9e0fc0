"""The hiking task as small terms over torch tensors on the env's device (mjlab's
manager-based shape, light): ``state`` derives one per-step state from the physics,
``observations``, ``rewards``, ``terminations`` and ``events`` are tables of named
functions over it. Stateful terms own their buffers and a ``reset(ids)``. docs/env.md.
"""
