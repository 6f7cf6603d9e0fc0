"""``mode=play viewer=web``: a recorded play rollout served as an interactive 3-D page.

The rollout is computed once (:func:`legoh.play.record_rollout`) and replayed: ``scene``
turns it into meshes and per-frame body poses, ``server`` serves them with viser (trail,
robots, waypoints, terminus, caption, depth inset, playback, follow camera, trail and level
selector). Nothing here is imported by the envs or the policies (one direction).
"""
