"""wott-hub driver plugin: the TacLink-style barrel vision skin (docs/barrel-vision.md).

Modules: ``geometry`` (markers on the mesh, fisheye cameras), ``simulator``
(both camera images of a scripted scene), ``estimator`` (detect, track,
model), ``model`` (ONNX contract and inference), ``driver``, ``settings``,
``plugin`` (the hooks); ``dataset``, ``training`` and ``onnx_export`` make the
default model (``scripts/train_model.py``).
"""
