"""``wott-hub bench accuracy``: contacts, actions and speeds against the ground truth of scripted scenes.

Every device family plays the same kinds of scene (``cases``) through its own driver
(``families``: the ground-truth ``scene`` pad and barrel, the camera-simulated flat pad and
barrel, the taxel array over a real pty); the frames are recorded once with the truth of
each (``truth``) and then processed by ``FrameProcessor`` under each setting compared
(``variants``), so every setting is scored on the same frames. ``score`` matches contacts to
the scene's indenters and counts; ``tables`` writes the report.
"""
