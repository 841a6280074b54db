"""Learning datasets from history: LeRobotDataset v3.0 and the diffusion-policy zarr replay buffer.

One job a module, no module imports this package's ``__init__`` (it holds only this map):
``episodes.py`` (episode marks and ranges), ``resample.py`` (zero-order hold onto a frame grid),
``features.py`` (a recorded stream's features), ``plan.py`` (which sources and columns an export has),
``stats.py`` (lerobot's statistics), ``video.py`` (camera videos, PyAV), ``lerobot_files.py`` and
``lerobot.py`` (the LeRobot layout and its writer), ``replay_buffer.py`` (the zarr layout), ``card.py``
(the dataset card), ``export.py`` (the export: checks, episodes, the loop, the folder renamed when
complete). pyarrow, PyAV and zarr are imported only inside an export (docs/learning.md).
"""
