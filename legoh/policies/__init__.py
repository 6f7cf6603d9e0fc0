"""Policies: build the oracle and the students, load them from checkpoints, build the
student's env. Training (``legoh/train``), the benchmark (``legoh/eval``), ``mode=play``
and ``mode=export`` all come here for their networks; this room imports envs, modules,
config and checkpoints, never train or eval.

- ``pretrained.py``: the shipped files (``pretrained/<robot>_<stage>.pt``)
- ``oracle.py``: the oracle's actor, critic and adaptation module, fresh or from a checkpoint
- ``student.py``: a student (LEGO-H or a baseline), its depth env, fresh or from a checkpoint
"""
