"""``mode=play viewer=web``: a recorded play rollout served as an interactive 3-D page.

The rollout is computed once (:func:`legoh.play.record_rollout`) and replayed: ``scene``
turns it into meshes and per-step body poses (no viser), ``nodes`` into viser scene nodes,
``server`` serves them with the side panel (caption, depth inset, playback, follow camera,
trail and level selector) and ``cli`` is the command. Nothing here is imported by the envs
or the policies (one direction).
"""
